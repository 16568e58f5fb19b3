"""Fixed bin edges of the load collectives, so drives and trucks sum and compare bin by bin.

Every axis is ``low … high`` in steps of ``width``, with ``low`` a multiple of the width: its bins
are bins ``k·width ≤ x < (k+1)·width`` of the fleet's sparse histograms (`fleet.LoadBins` takes
its widths from `WIDTHS`), so a drive's collective is the fleet's histogram cut to a range, values
beyond it counted in the end bins. The widths are one for all trucks; the range is the vehicle
class's (`CLASS_RANGES`, chosen by gross mass) **[choice: the wheel forces a truck of the class can
reach: braking at 0.8 g at its gross mass, wheel speed up to 700 rpm (about 130 km/h on 0.5 m
wheels)]**. A TOML file overrides any axis (`read_overrides`).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..vehicle import Vehicle

WIDTHS = {
    "wheel_force_n": 1000.0, "wheel_torque_nm": 500.0, "wheel_speed_rpm": 10.0, "wheel_power_w": 10_000.0,
    "residence_speed_rpm": 25.0, "residence_torque_nm": 2500.0, "rainflow_range_nm": 2500.0,
    "rainflow_mean_nm": 2500.0,
}
"""Bin width of each axis, in the unit its name ends in."""
ARTICULATED_MIN_GROSS_KG = 26_000.0
"""Gross mass above which a truck counts as articulated (tractor-semitrailer, truck-trailer) [kg];
the heaviest rigid trucks in the EU are 26 t (32 t with four axles, rare)."""
CLASS_RANGES = {
    "rigid": {"wheel_force_n": (-150e3, 150e3), "wheel_torque_nm": (-75e3, 75e3), "wheel_speed_rpm": (0.0, 700.0),
              "wheel_power_w": (-1.0e6, 1.0e6), "residence_speed_rpm": (0.0, 700.0),
              "residence_torque_nm": (-75e3, 75e3), "rainflow_range_nm": (0.0, 150e3),
              "rainflow_mean_nm": (-75e3, 75e3)},
    "articulated": {"wheel_force_n": (-300e3, 300e3), "wheel_torque_nm": (-150e3, 150e3),
                    "wheel_speed_rpm": (0.0, 700.0), "wheel_power_w": (-2.0e6, 2.0e6),
                    "residence_speed_rpm": (0.0, 700.0), "residence_torque_nm": (-150e3, 150e3),
                    "rainflow_range_nm": (0.0, 300e3), "rainflow_mean_nm": (-150e3, 150e3)},
}
"""(low, high) of each axis per vehicle class, in the unit its name ends in."""
MAX_BINS = 10_000


class LoadBinsError(UserError):
    pass


@dataclass(frozen=True)
class Axis:
    """Bins ``low … high`` of ``width`` (``low`` and ``high`` multiples of ``width``)."""

    low: float
    high: float
    width: float

    def edges(self) -> np.ndarray:
        first = round(self.low / self.width)
        return (first + np.arange(round((self.high - self.low) / self.width) + 1)) * self.width

    def check(self, where: str) -> "Axis":
        if not (np.isfinite([self.low, self.high, self.width]).all() and self.width > 0 and self.high > self.low):
            raise LoadBinsError(f"{where}: needs width > 0 and high > low (got low={self.low:g}, high={self.high:g}, "
                                f"width={self.width:g})")
        for name in ("low", "high"):
            steps = getattr(self, name) / self.width
            if abs(steps - round(steps)) > 1e-9 * max(1.0, abs(steps)):
                raise LoadBinsError(f"{where}: {name}={getattr(self, name):g} is not a multiple of width="
                                    f"{self.width:g} (bins must lie on the fleet's k·width grid)")
        if (self.high - self.low) / self.width > MAX_BINS:
            raise LoadBinsError(f"{where}: {(self.high - self.low) / self.width:.0f} bins, more than {MAX_BINS}")
        return self


@dataclass(frozen=True)
class LoadEdges:
    """The axes of every collective."""

    vehicle_class: str
    wheel_force_n: Axis
    wheel_torque_nm: Axis
    wheel_speed_rpm: Axis
    wheel_power_w: Axis
    residence_speed_rpm: Axis
    residence_torque_nm: Axis
    rainflow_range_nm: Axis
    rainflow_mean_nm: Axis

    def arrays(self) -> dict[str, np.ndarray]:
        """Edges per axis name (what `loads.summary.compute` takes)."""
        return {f.name: getattr(self, f.name).edges() for f in fields(self) if f.name != "vehicle_class"}

    def as_dict(self) -> dict:
        return {"vehicle_class": self.vehicle_class,
                **{f.name: vars(getattr(self, f.name)) for f in fields(self) if f.name != "vehicle_class"}}


def vehicle_class(vehicle: Vehicle) -> str:
    """``articulated`` above `ARTICULATED_MIN_GROSS_KG` of gross mass (curb + max payload), else ``rigid``."""
    gross = vehicle.curb_mass_kg + (vehicle.max_payload_kg or 0.0)
    return "articulated" if gross > ARTICULATED_MIN_GROSS_KG else "rigid"


def class_edges(name: str) -> LoadEdges:
    ranges = CLASS_RANGES[name]
    return LoadEdges(name, **{axis: Axis(*ranges[axis], WIDTHS[axis]) for axis in WIDTHS})


def default_edges(vehicle: Vehicle) -> LoadEdges:
    return class_edges(vehicle_class(vehicle))


def read_overrides(path: Path) -> tuple:
    """The axes a TOML file sets: a table per axis (``[wheel_torque_nm]``) with any of ``low``,
    ``high`` and ``width`` in the axis's unit; as ``((axis, ((key, value), …)), …)`` (an option value
    the stage cache keys by content)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise LoadBinsError(f"load bins file {path} not found") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise LoadBinsError(f"{path}: cannot read as TOML ({exc})") from None
    overrides = []
    for axis, table in data.items():
        if axis not in WIDTHS:
            raise LoadBinsError(f"{path}: unknown table [{axis}] (known: {', '.join(WIDTHS)})")
        if not isinstance(table, dict) or set(table) - {"low", "high", "width"}:
            raise LoadBinsError(f"{path} [{axis}]: keys are low, high, width")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in table.values()):
            raise LoadBinsError(f"{path} [{axis}]: low, high and width are numbers")
        overrides.append((axis, tuple(sorted((k, float(v)) for k, v in table.items()))))
    apply_overrides(class_edges("rigid"), tuple(overrides), str(path))
    return tuple(overrides)


def apply_overrides(base: LoadEdges, overrides: tuple, where: str = "load bins") -> LoadEdges:
    """``base`` with the axes of `read_overrides` replaced (each checked: one-line error naming the axis)."""
    changes = {axis: replace(getattr(base, axis), **dict(values)).check(f"{where} [{axis}]")
               for axis, values in overrides}
    return replace(base, **changes)
