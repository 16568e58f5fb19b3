"""Cycles for the simulator: distance-based (VECTO ``.vdri``) and time-based speed traces, as
the row arrays the kernel reads, with the road forces (2)-(3) from `analysis.road_load`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .. import road_load
from ..errors import UserError
from ..signals import SIGNALS_SUFFIXES, read_signals
from ..vecto import read_vdri
from ..vehicle import Vehicle


class SimulationInputError(UserError):
    pass


@dataclass(frozen=True)
class SimCycle:
    """A cycle ready for the kernel. ``position`` is distance [m] (distance-based) or time [s]."""

    name: str
    time_based: bool
    position: np.ndarray
    target_speed_mps: np.ndarray
    gradient_pct: np.ndarray
    mass_kg: np.ndarray
    stop_distance_m: np.ndarray
    stop_time_s: np.ndarray

    def road_forces_n(self, vehicle: Vehicle) -> tuple[np.ndarray, np.ndarray]:
        """(F_roll (2), F_climb (3)) per row [N]."""
        return (np.asarray(road_load.rolling_force_n(self.mass_kg, self.gradient_pct,
                                                     vehicle.rolling_resistance_coefficient), float),
                np.asarray(road_load.climbing_force_n(self.mass_kg, self.gradient_pct), float))


def default_mass_kg(vehicle: Vehicle, payload_kg: float | None = None) -> float:
    """Total mass [kg]: curb mass plus ``payload_kg``, by default half the maximum payload."""
    if payload_kg is None:
        payload_kg = 0.5 * (vehicle.max_payload_kg or 0.0)
    return vehicle.curb_mass_kg + payload_kg


def distance_cycle(frame: pd.DataFrame, mass_kg, name: str = "cycle") -> SimCycle:
    """Distance-based cycle from `analysis.vecto` SI columns and a mass [kg] (constant or per
    row). A row with target 0 is a stop point
    (standstill ``stop_time_s``); the segment after it takes the next row's target speed."""
    distance = frame["distance_m"].to_numpy(float)
    target = frame["target_speed_mps"].to_numpy(float).copy()
    stop = frame["stop_time_s"].to_numpy(float)
    if len(distance) < 2:
        raise SimulationInputError(f"{name}: a distance-based cycle needs at least two rows")
    is_stop = target <= 1e-9
    nonzero = np.where(~is_stop, target, np.nan)
    following = pd.Series(nonzero).bfill().ffill().fillna(0.0).to_numpy()
    target[is_stop] = following[is_stop]
    stop_rows = np.flatnonzero(is_stop | (stop > 0))
    return SimCycle(name, False, distance, target, frame["gradient_pct"].to_numpy(float),
                    np.broadcast_to(np.asarray(mass_kg, float), distance.shape).copy(),
                    distance[stop_rows], stop[stop_rows])


def time_cycle(frame: pd.DataFrame, default_mass: float, name: str = "cycle") -> SimCycle:
    """Time-based cycle from ``time_s``, ``speed_mps`` [, ``gradient_pct``, ``mass_kg``]."""
    for column in ("time_s", "speed_mps"):
        if column not in frame.columns:
            raise SimulationInputError(f"{name}: a time-based cycle needs columns time_s and speed_mps "
                                       f"(missing {column})")
    frame = frame.dropna(subset=["time_s", "speed_mps"])
    time = frame["time_s"].to_numpy(float)
    if len(time) < 2 or np.any(np.diff(time) <= 0):
        raise SimulationInputError(f"{name}: time_s must rise strictly over at least two rows")
    speed = np.clip(frame["speed_mps"].to_numpy(float), 0.0, None)
    gradient = (frame["gradient_pct"].fillna(0.0).to_numpy(float) if "gradient_pct" in frame.columns
                else np.zeros(len(time)))
    mass = (frame["mass_kg"].ffill().bfill().fillna(default_mass).to_numpy(float) if "mass_kg" in frame.columns
            else np.full(len(time), float(default_mass)))
    return SimCycle(name, True, time, speed, gradient, mass, np.empty(0), np.empty(0))


def read_cycle(path: str | Path, vehicle: Vehicle, payload_kg: float | None = None) -> SimCycle:
    """A ``.vdri`` (distance-based), or a CSV/Parquet time-based trace or signals table.

    Parameters
    ----------
    path : str or Path
        VECTO ``.vdri`` (``<s>,<v>,<grad>,<stop>``), or a CSV/Parquet with ``time_s`` [s],
        ``speed_mps`` [m/s] and optionally ``gradient_pct`` [%], ``mass_kg`` [kg].
    vehicle : Vehicle
        For the default mass.
    payload_kg : float, optional
        Payload [kg] where the cycle has no mass; default half the vehicle's maximum payload.

    Returns
    -------
    SimCycle
        The rows the simulation kernel reads, with the road forces of paper equations (2)-(3).
    """
    path = Path(path)
    mass = default_mass_kg(vehicle, payload_kg)
    if not path.is_file():
        raise SimulationInputError(f"cycle {path} not found")
    if path.suffix.lower() == ".vdri":
        return distance_cycle(read_vdri(path), mass, path.stem)
    if path.suffix.lower() not in SIGNALS_SUFFIXES:
        raise SimulationInputError(f"{path}: give a .vdri, or a .csv/.parquet with time_s and speed_mps")
    if path.suffix.lower() == ".csv":
        try:
            header = pd.read_csv(path, nrows=0).columns
        except (ValueError, UnicodeDecodeError) as exc:  # pandas' ParserError and EmptyDataError are ValueErrors
            raise SimulationInputError(f"{path}: not a readable CSV table ({type(exc).__name__})") from None
        if all(h in header for h in ("<s>", "<v>", "<grad>", "<stop>")):
            return distance_cycle(read_vdri(path), mass, path.stem)
    frame = read_signals(path)
    return time_cycle(frame, mass, path.stem)
