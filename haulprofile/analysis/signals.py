"""The signals table: one row per sample, SI units; what every stage reads and writes.

Accepted as input wherever a log is, so data from other loggers can be analysed. ``time_s`` and
``speed_mps`` are required; the optional columns below switch stages on; unknown columns are kept.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .errors import UserError

REQUIRED = {"time_s": "time since the start of the log [s]", "speed_mps": "vehicle speed [m/s]"}
OPTIONAL = {
    "engine_speed_rpm": "engine speed [rpm]",
    "engine_torque_nm": "actual engine torque [Nm]",
    "latitude_deg": "GPS latitude [deg]",
    "longitude_deg": "GPS longitude [deg]",
    "gps_altitude_m": "GPS altitude [m]",
    "gps_h_acc_m": "GPS horizontal accuracy [m]",
    "gps_v_acc_m": "GPS vertical accuracy [m]",
    "pressure_pa": "barometric pressure [Pa]",
    "air_temperature_c": "air temperature [degC]",
    "accel_x_mps2": "longitudinal IMU acceleration [m/s^2]",
    "reported_mass_kg": "the vehicle's own mass estimate (J1939 VW/CVW) [kg]",
}
DERIVED = {
    "wall_time_ns": "wall-clock time (GPS UTC where known) [ns since epoch]",
    "valid": "sample backed by data (False inside gaps)",
    "distance_m": "driven distance from wheel speed [m]",
    "accel_mps2": "longitudinal acceleration from wheel speed [m/s^2]",
    "height_m": "fused road height [m]",
    "gradient_pct": "fused road gradient [%]",
    "mass_kg": "estimated total vehicle mass [kg]",
}
COLUMNS = {**REQUIRED, **OPTIONAL, **DERIVED}

SIGNALS_SUFFIXES = {".csv", ".parquet", ".pq"}


class SignalsError(UserError):
    pass


def validate(frame: pd.DataFrame, source: str = "signals table") -> pd.DataFrame:
    """Check required columns, numeric types and monotonic time; return the frame sorted by time."""
    missing = [c for c in REQUIRED if c not in frame.columns]
    if missing:
        raise SignalsError(f"{source}: missing required column(s) {', '.join(missing)} "
                           f"(a signals table needs time_s [s] and speed_mps [m/s])")
    for column in frame.columns:
        if column in COLUMNS and column != "valid" and not pd.api.types.is_numeric_dtype(frame[column]):
            raise SignalsError(f"{source}: column {column} must be numeric ({COLUMNS[column]})")
    if len(frame) == 0:
        raise SignalsError(f"{source}: has no rows")
    time = frame["time_s"].to_numpy()
    if not np.all(np.isfinite(time)):
        raise SignalsError(f"{source}: time_s has missing or infinite values")
    if np.any(np.diff(time) < 0):
        frame = frame.sort_values("time_s", kind="stable").reset_index(drop=True)
    return frame


def missing_for(frame: pd.DataFrame, needed: list[str]) -> list[str]:
    """Columns of ``needed`` that are absent or all-NaN."""
    return [c for c in needed if c not in frame.columns or frame[c].isna().all()]


def read_signals(path: str | Path) -> pd.DataFrame:
    """Read a signals table from CSV or Parquet and validate it.

    Parameters
    ----------
    path : str or Path
        ``.csv``, ``.parquet`` or ``.pq`` with at least ``time_s`` [s] and ``speed_mps`` [m/s].

    Returns
    -------
    DataFrame
        One row per sample in SI units (`COLUMNS`), sorted by ``time_s``; `SignalsError` (one
        line) for a missing column, a non-numeric column or missing time stamps.
    """
    path = Path(path)
    if not path.is_file():
        raise SignalsError(f"signals table {path} not found")
    try:
        if path.suffix.lower() == ".csv":
            frame = pd.read_csv(path)
        else:
            frame = pd.read_parquet(path)
    except Exception as exc:  # pandas/pyarrow raise many types for unreadable files
        raise SignalsError(f"{path}: cannot read as {path.suffix[1:]} table: {exc}") from None
    return validate(frame, str(path))


POSITION_COLUMNS = ("latitude_deg", "longitude_deg", "wall_time_ns")
"""What ``analyze run --private`` keeps out of its outputs: where and when (heights, gradients,
distances and times since the start stay)."""


def without_positions(frame: pd.DataFrame) -> pd.DataFrame:
    return frame.drop(columns=[c for c in POSITION_COLUMNS if c in frame.columns])


def write_signals(frame: pd.DataFrame, path: str | Path) -> Path:
    """Write a signals table; the suffix (.csv or .parquet) chooses the format.

    Parameters
    ----------
    frame : DataFrame
        A signals table (SI columns, `COLUMNS`).
    path : str or Path
        Where; its folder is made.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".csv":
        frame.to_csv(path, index=False)
    else:
        frame.to_parquet(path, index=False)
    return path


def is_signals_path(path: str | Path) -> bool:
    return Path(path).suffix.lower() in SIGNALS_SUFFIXES
