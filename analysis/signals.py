"""The signals table: one row per sample, SI units; what every stage reads and writes.

Accepted as input wherever a log is, so data from other loggers can be analysed. ``time_s`` and
``speed_mps`` are required; the optional columns below switch stages on; unknown columns are kept.
"""

from __future__ import annotations

import re

from pathlib import Path

import numpy as np
import pandas as pd

from . import units
from .errors import UserError
from .signal_columns import COLUMNS, REQUIRED


SIGNALS_SUFFIXES = {".csv", ".parquet", ".pq"}
CYCLE_SUFFIXES = {".vdri"}
"""Read as a signals table too: a VECTO distance-based cycle becomes its 1 Hz time trace (time_s,
distance_m, speed_mps, gradient_pct), so a standard cycle goes wherever a drive does."""
MAX_SPEED_MPS = 70.0
"""Fastest plausible road vehicle speed [m/s] (252 km/h); trucks are limited to some 25-35 m/s."""
MAX_SAMPLE_INTERVAL_S = 60.0
"""Longest median interval between samples of a drive [s]; longer means time_s is not in seconds."""
MAX_SPAN_S = 5 * 366 * 86400.0
"""Longest time a table may span [s] (five years)."""
MIN_SPEED_MPS = -0.5
"""Wheel-based speed is not signed; small negative values are sensor noise, larger ones a fault [m/s]."""


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
    if len(frame) == 1:
        raise SignalsError(f"{source}: has a single row; a drive needs at least two samples")
    time = frame["time_s"].to_numpy(dtype=float)
    if not np.all(np.isfinite(time)):
        raise SignalsError(f"{source}: time_s has missing or infinite values")
    step = np.diff(time)
    if np.any(step < 0):
        row = int(np.flatnonzero(step < 0)[0]) + 1
        raise SignalsError(f"{source}: time_s goes backwards at row {row} ({time[row]:g} s after {time[row - 1]:g} s); "
                           f"sort the table by time or fix its clock")
    if np.median(step) > MAX_SAMPLE_INTERVAL_S or time[-1] - time[0] > MAX_SPAN_S:
        raise SignalsError(f"{source}: time_s spans {time[-1] - time[0]:.3g} s with a median step of "
                           f"{np.median(step):.3g} s; is it in seconds?")
    if np.any(step == 0):
        row = int(np.flatnonzero(step == 0)[0]) + 1
        raise SignalsError(f"{source}: time_s has {int((step == 0).sum())} duplicated time stamp(s), the first "
                           f"{time[row]:g} s at row {row}; give each sample its own time")
    _check_speed(frame["speed_mps"].to_numpy(dtype=float), source)
    return frame


def _check_speed(speed: np.ndarray, source: str) -> None:
    finite = speed[np.isfinite(speed)]
    if len(finite) == 0:
        raise SignalsError(f"{source}: speed_mps has no values (all empty or NaN)")
    if finite.min() < MIN_SPEED_MPS:
        raise SignalsError(f"{source}: speed_mps has {int((finite < MIN_SPEED_MPS).sum())} negative value(s) down to "
                           f"{finite.min():g} m/s; vehicle speed is not signed")
    if finite.max() > MAX_SPEED_MPS:
        raise SignalsError(f"{source}: speed_mps reaches {finite.max():g} m/s, above {MAX_SPEED_MPS:g} m/s "
                           f"({MAX_SPEED_MPS * 3.6:.0f} km/h); is it in m/s?")
    if np.isinf(speed).any():
        raise SignalsError(f"{source}: speed_mps has infinite values")


def combine(paths, say=None) -> pd.DataFrame:
    """Read signals tables, drop any whose content repeats an earlier one (with a warning), and join
    them in time order; tables that overlap in time are refused."""
    from .checks import drop_same_content

    paths = drop_same_content([Path(p) for p in paths], say)
    frames = sorted((read_signals(p) for p in paths), key=lambda f: float(f["time_s"].iloc[0]))
    from .plausible import check_ranges

    source = ", ".join(map(str, paths))
    return shorten_silences(check_ranges(validate(pd.concat(frames, ignore_index=True), source), source, say), say)


def shorten_silences(frame: pd.DataFrame, say=None) -> pd.DataFrame:
    """Silences longer than the ingest's `MAX_GAP_S` shortened to `KEPT_GAP_S`, as the logs' are
    (`ingest.align.Grid`): a table with a month between two drives would otherwise be resampled
    over the month (gigabytes of empty rows). Wall-clock time, if the table has it, stays."""
    from .ingest.align import KEPT_GAP_S, MAX_GAP_S

    time = frame["time_s"].to_numpy(dtype=float)
    step = np.diff(time)
    long = step > MAX_GAP_S
    if not long.any():
        return frame
    removed = np.concatenate([[0.0], np.cumsum(np.where(long, step - KEPT_GAP_S, 0.0))])
    frame = frame.copy()
    frame["time_s"] = time - removed
    if say is not None:
        say(f"signals table: {int(long.sum())} silence(s) longer than {MAX_GAP_S:g} s shortened to {KEPT_GAP_S:g} s "
            f"({removed[-1] / 86400:.3g} days left out of time_s, as for logs)")
    return frame


def describe(frame: pd.DataFrame) -> dict:
    """Rows, duration [s], rate [Hz], valid share and per-column coverage of a signals table."""
    time = frame["time_s"].to_numpy(dtype=float)
    step = float(np.median(np.diff(time))) if len(time) > 1 else float("nan")
    valid = (frame["valid"].fillna(False).to_numpy(bool) if "valid" in frame.columns
             else np.isfinite(frame["speed_mps"].to_numpy(dtype=float)))
    coverage = {c: float(np.isfinite(pd.to_numeric(frame[c], errors="coerce").to_numpy(dtype=float))[valid].mean())
                if valid.any() else 0.0 for c in frame.columns if c not in ("time_s", "valid", "wall_time_ns")}
    return {"rows": int(len(frame)), "duration_s": float(time[-1] - time[0] + (step if np.isfinite(step) else 0.0)),
            "rate_hz": 1.0 / step if step > 0 else 0.0, "valid_fraction": float(valid.mean()), "coverage": coverage}


def missing_for(frame: pd.DataFrame, needed: list[str]) -> list[str]:
    """Columns of ``needed`` that are absent or all-NaN."""
    return [c for c in needed if c not in frame.columns or frame[c].isna().all()]


def read_signals(path: str | Path) -> pd.DataFrame:
    """Read a signals table from CSV or Parquet and validate it.

    Parameters
    ----------
    path : str or Path
        ``.csv``, ``.parquet`` or ``.pq`` with at least ``time_s`` [s] and ``speed_mps`` [m/s], or
        a VECTO ``.vdri`` cycle (`CYCLE_SUFFIXES`).

    Returns
    -------
    DataFrame
        One row per sample in SI units (`COLUMNS`), sorted by ``time_s``; `SignalsError` (one
        line) for a missing column, a non-numeric column or missing time stamps.
    """
    path = Path(path)
    if not path.is_file():
        raise SignalsError(f"signals table {path} not found")
    if path.suffix.lower() in CYCLE_SUFFIXES:
        from .vecto import read_vdri, vdri_to_time_cycle

        return validate(vdri_to_time_cycle(read_vdri(path)), str(path))
    try:
        if path.suffix.lower() == ".csv":
            frame = pd.read_csv(path)
        else:
            frame = pd.read_parquet(path)
    except Exception as exc:  # pandas/pyarrow raise many types for unreadable files
        raise SignalsError(f"{path}: cannot read as {path.suffix[1:]} table: {exc}") from None
    known = units.read_sidecar(path) if path.suffix.lower() == ".csv" else units.parquet_units(path)
    frame.attrs[units.UNITS_KEY] = {c: u for c, u in known.items() if c in frame.columns and u != units.unit_of(c)}
    return validate(frame, str(path))


POSITION_COLUMNS = ("latitude_deg", "longitude_deg", "wall_time_ns")
"""What ``analyze run --private`` keeps out of its outputs: where and when (heights, gradients,
distances and times since the start stay)."""


_POSITION_WORDS = {"lat", "latitude", "lon", "lng", "longitude", "utc", "gmt", "wall", "date", "datetime",
                   "timestamp", "epoch"}
_CLOCK_WORDS = {"second", "seconds", "minute", "minutes", "hour", "hours", "day", "days", "month", "year",
                "local", "offset", "of"}
"""A column made of these words only is a wall-clock reading (J1939 Time/Date decoded by a DBC)."""


def _words(name: str) -> list[str]:
    return [w.lower() for w in re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|\d+", str(name))]


def is_position_column(name: str) -> bool:
    """A column that tells where or when (of day): ours (`POSITION_COLUMNS`) or one a foreign table or
    a DBC brings (``lat``, ``Longitude``, ``gps_time_utc``, ``VP_Latitude``, ``Hours``+``Minutes``)."""
    words = _words(name)
    if name in POSITION_COLUMNS or not words:
        return name in POSITION_COLUMNS
    return (bool(_POSITION_WORDS & set(words)) or words == ["long"] or {"gps", "time"} <= set(words)
            or set(words) <= _CLOCK_WORDS)


def without_positions(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` without every column that tells where or when (`is_position_column`)."""
    return frame.drop(columns=[c for c in frame.columns if is_position_column(c)])


def write_signals(frame: pd.DataFrame, path: str | Path) -> Path:
    """Write a signals table; the suffix (.csv, or .parquet/.pq) chooses the format, any other is refused.

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
    if path.suffix.lower() not in SIGNALS_SUFFIXES:
        raise SignalsError(f"{path}: a signals table ends in {', '.join(sorted(SIGNALS_SUFFIXES))}, "
                           f"not {path.suffix or '(no suffix)'}")
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".csv":
        frame.to_csv(path, index=False)
        units.write_sidecar(frame, path)
    else:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pandas(frame, preserve_index=False)
        pq.write_table(units.parquet_schema(table, units.column_units(frame)), path)
    return path


def is_signals_path(path: str | Path) -> bool:
    """A table by its suffix (a VECTO cycle counts as one); a ``.csv`` that python-can wrote (its CAN
    log header) is a log, not a table."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SIGNALS_SUFFIXES | CYCLE_SUFFIXES:
        return False
    if suffix == ".csv" and path.is_file():
        from .ingest.foreign import kind

        return kind(path) is None
    return True
