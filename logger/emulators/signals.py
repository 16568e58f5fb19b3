"""Time series that feed the emulators: a mapping of column name to array, with ``time_s``."""

from __future__ import annotations

from bisect import bisect_right
from typing import Mapping

import numpy as np

ALIASES = {
    "vehicle_speed_kmh": ("wheel_speed_kmh", "vehicle_speed_kmh"),
    "barometric_pressure_kpa": ("barometric_pressure_kpa",),
    "ambient_air_temperature_c": ("ambient_air_temperature_c", "air_temperature_c", "temperature_c"),
}


class TimeSeries:
    """Sample-and-hold lookup of named signals at a time [s] from the start of the series."""

    def __init__(self, columns: Mapping[str, np.ndarray]):
        if "time_s" not in columns:
            raise ValueError("emulator signals need a time_s column")
        self.time_s = np.asarray(columns["time_s"], dtype=float)
        self._times = self.time_s.tolist()  # bisect on a list: a lookup per frame, no NumPy call
        self.columns = {k: np.asarray(v) for k, v in columns.items() if k != "time_s"}
        if "speed_mps" in self.columns and "wheel_speed_kmh" not in self.columns:
            self.columns["wheel_speed_kmh"] = self.columns["speed_mps"] * 3.6
        if "pressure_pa" in self.columns and "barometric_pressure_kpa" not in self.columns:
            self.columns["barometric_pressure_kpa"] = self.columns["pressure_pa"] / 1000.0

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])

    def has(self, name: str) -> bool:
        return any(a in self.columns for a in ALIASES.get(name, (name,)))

    def index(self, t_s: float) -> int:
        i = bisect_right(self._times, self._times[0] + t_s) - 1
        return min(max(i, 0), len(self._times) - 1)

    def value(self, name: str, t_s: float, default=None):
        for alias in ALIASES.get(name, (name,)):
            if alias in self.columns:
                return float(self.columns[alias][self.index(t_s)])
        return default

    def values(self, names, t_s: float) -> dict:
        i = self.index(t_s)
        out = {}
        for name in names:
            for alias in ALIASES.get(name, (name,)):
                if alias in self.columns:
                    out[name] = float(self.columns[alias][i])
                    break
        return out


def merge(frames: Mapping[str, Mapping[str, np.ndarray]], step_s: float = 0.01) -> dict[str, np.ndarray]:
    """One table of columns from several tables with their own ``time_s`` (sample-and-hold)."""
    end = max(float(np.asarray(f["time_s"])[-1]) for f in frames.values())
    start = min(float(np.asarray(f["time_s"])[0]) for f in frames.values())
    time_s = np.arange(start, end + step_s / 2, step_s)
    out = {"time_s": time_s}
    for frame in frames.values():
        t = np.asarray(frame["time_s"], dtype=float)
        idx = np.clip(np.searchsorted(t, time_s, side="right") - 1, 0, len(t) - 1)
        for name, column in frame.items():
            if name != "time_s" and name not in out:
                out[name] = np.asarray(column)[idx]
    return out


def from_streams(streams: Mapping[str, object], step_s: float = 0.01) -> dict[str, np.ndarray]:
    """Emulator columns from sensor streams (tables with ``time_s``, e.g. a virtual drive's
    ``sensors`` DataFrames) and constants (scalars, e.g. ``engine_reference_torque_nm``)."""
    tables = {k: v for k, v in streams.items() if hasattr(v, "__getitem__") and _has_time(v)}
    columns = merge({k: {c: np.asarray(v[c]) for c in v.keys()} for k, v in tables.items()}, step_s)
    for name, value in streams.items():
        if name not in tables and np.isscalar(value):
            columns.setdefault(name, np.full(columns["time_s"].size, float(value)))
    return columns


def stream_rate_hz(streams: Mapping[str, object], name: str) -> float | None:
    """The median sample rate of table ``name`` in ``streams`` (``time_s`` [s]), or None [Hz]."""
    table = streams.get(name)
    if table is None or not _has_time(table):
        return None
    steps = np.diff(np.asarray(table["time_s"], dtype=float))
    steps = steps[steps > 0]
    return float(1.0 / np.median(steps)) if steps.size else None


def _has_time(table) -> bool:
    try:
        return "time_s" in table.keys()
    except AttributeError:
        return False


def synthetic_drive(duration_s: float = 600.0, seed: int = 7) -> dict[str, np.ndarray]:
    """A plausible truck drive (speed, engine, weather, position) without the analysis package."""
    rng = np.random.default_rng(seed)
    time_s = np.arange(0.0, duration_s, 0.01)
    speed_mps = np.clip(22.0 * (1 - np.exp(-time_s / 60.0)) + 2.0 * np.sin(time_s / 37.0), 0, None)
    engine_speed_rpm = 600.0 + 45.0 * speed_mps + 20.0 * np.sin(time_s / 3.0)
    torque_pct = np.clip(40 + 30 * np.sin(time_s / 11.0) + rng.normal(0, 2, time_s.size), -50, 100)
    distance_m = np.cumsum(speed_mps) * 0.01
    return {
        "time_s": time_s,
        "speed_mps": speed_mps,
        "engine_speed_rpm": engine_speed_rpm,
        "actual_engine_torque_pct": torque_pct,
        "driver_demand_torque_pct": torque_pct + 2.0,
        "engine_reference_torque_nm": np.full(time_s.size, 2400.0),
        "fuel_rate_lph": np.clip(5 + 0.4 * torque_pct, 0, None),
        "gross_combination_weight_kg": np.full(time_s.size, 18000.0),
        "pressure_pa": 95000.0 - 0.012 * distance_m,
        "temperature_c": 12.0 + 0.001 * time_s,
        "relative_humidity_pct": 60.0 + 5 * np.sin(time_s / 100.0),
        "accel_x_mps2": np.gradient(speed_mps, 0.01) + rng.normal(0, 0.05, time_s.size),
        "accel_y_mps2": rng.normal(0, 0.05, time_s.size),
        "accel_z_mps2": 9.80665 + rng.normal(0, 0.05, time_s.size),
        "gyro_z_radps": 0.01 * np.sin(time_s / 20.0),
        "latitude_deg": 48.137 + distance_m / 111_320.0,
        "longitude_deg": np.full(time_s.size, 11.575),
        "altitude_m": 520.0 + 0.01 * distance_m,
        "h_acc_m": np.full(time_s.size, 2.5),
        "v_acc_m": np.full(time_s.size, 4.0),
    }
