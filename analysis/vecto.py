"""VECTO distance-based driving cycles (``.vdri``): ``<s>,<v>,<grad>,<stop>``.

``<s>`` distance [m], ``<v>`` target speed [km/h], ``<grad>`` road gradient [%], ``<stop>`` standstill
time [s] at that distance (a stop is a row with v = 0 and stop > 0). Inside the code the cycle is a
DataFrame in SI units: ``distance_m``, ``target_speed_mps``, ``gradient_pct``, ``stop_time_s``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .errors import UserError

KMH_PER_MPS = 3.6
MIN_STEP_M = 1.0
"""VECTO's distance resolution: ``<s>`` rises by at least this much from row to row [m]."""
HEADER = ("<s>", "<v>", "<grad>", "<stop>")
COLUMNS = ("distance_m", "target_speed_mps", "gradient_pct", "stop_time_s")


class CycleFileError(UserError):
    pass


def read_vdri(path: str | Path) -> pd.DataFrame:
    """Read a VECTO distance-based cycle into SI columns (`COLUMNS`).

    Parameters
    ----------
    path : str or Path
        A ``.vdri`` with the columns ``<s>`` [m], ``<v>`` [km/h], ``<grad>`` [%], ``<stop>`` [s].

    Returns
    -------
    DataFrame
        ``distance_m`` [m], ``target_speed_mps`` [m/s], ``gradient_pct`` [%], ``stop_time_s`` [s].
    """
    path = Path(path)
    if not path.is_file():
        raise CycleFileError(f"cycle file {path} not found")
    try:
        raw = pd.read_csv(path, comment="#", skipinitialspace=True)
    except Exception as exc:
        raise CycleFileError(f"{path}: cannot read as a VECTO cycle: {exc}") from None
    raw.columns = [c.strip() for c in raw.columns]
    missing = [h for h in HEADER if h not in raw.columns]
    if missing:
        raise CycleFileError(f"{path}: not a distance-based VECTO cycle, missing column(s) {', '.join(missing)}")
    values = raw[list(HEADER)].apply(pd.to_numeric, errors="coerce")
    if values.isna().any().any():
        row = int(values.isna().any(axis=1).to_numpy().argmax())
        raise CycleFileError(f"{path}: row {row + 2} has a value that is not a number")
    cycle = pd.DataFrame({
        "distance_m": values["<s>"].to_numpy(float),
        "target_speed_mps": values["<v>"].to_numpy(float) / KMH_PER_MPS,
        "gradient_pct": values["<grad>"].to_numpy(float),
        "stop_time_s": values["<stop>"].to_numpy(float),
    })
    if np.any(np.diff(cycle["distance_m"].to_numpy()) < 0):
        raise CycleFileError(f"{path}: distance <s> decreases; a VECTO cycle is sorted by distance")
    return cycle


def write_vdri(cycle: pd.DataFrame, path: str | Path) -> Path:
    """Write SI columns (`COLUMNS`) as a VECTO ``.vdri`` file.

    Parameters
    ----------
    cycle : DataFrame
        ``distance_m`` [m], ``target_speed_mps`` [m/s], ``gradient_pct`` [%], ``stop_time_s`` [s].
    path : str or Path
        Where; its folder is made.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    out = pd.DataFrame({
        "<s>": np.round(cycle["distance_m"].to_numpy(float), 2),
        "<v>": np.round(cycle["target_speed_mps"].to_numpy(float) * KMH_PER_MPS, 3),
        "<grad>": np.round(cycle["gradient_pct"].to_numpy(float), 4),
        "<stop>": np.round(cycle["stop_time_s"].to_numpy(float), 2),
    })
    out.to_csv(path, index=False)
    return path


def vdri_problems(path: str | Path) -> list[str]:
    """What makes a ``.vdri`` file break VECTO's rules for distance-based cycles (empty if none).

    The header is exactly ``<s>,<v>,<grad>,<stop>``; every value is a finite number; ``<s>`` rises by
    at least `MIN_STEP_M` from row to row; speeds and stop times are not negative; a row with a stop
    time is a standstill (v = 0), and every standstill but the last row (the end) has a stop time.
    """
    lines = Path(path).read_text().splitlines()
    if not lines or tuple(c.strip() for c in lines[0].split(",")) != HEADER:
        return [f"header is not {','.join(HEADER)}"]
    try:
        values = np.array([[float(x) for x in line.split(",")] for line in lines[1:]], dtype=float)
    except ValueError as exc:
        return [f"a value is not a number ({exc})"]
    if values.ndim != 2 or values.shape[1] != 4 or len(values) < 2:
        return ["needs at least two rows of four columns"]
    problems = []
    s, v, _grad, stop = values.T
    if not np.all(np.isfinite(values)):
        problems.append("non-finite values")
    short = np.flatnonzero(np.diff(s) < MIN_STEP_M)
    if short.size:
        problems.append(f"{short.size} distance step(s) under {MIN_STEP_M:g} m, first at row {short[0] + 3}")
    if np.any(v < 0) or np.any(stop < 0):
        problems.append("negative speed or stop time")
    if np.any((stop > 0) & (v > 0)):
        problems.append("stop time on a row with a target speed")
    if np.any((v[:-1] == 0) & (stop[:-1] <= 0)):
        problems.append("a standstill row without stop time")
    return problems


def vdri_to_time_cycle(vdri: pd.DataFrame) -> pd.DataFrame:
    """A VECTO cycle (SI columns, `read_vdri`) as a 1 Hz time trace: ``time_s`` [s],
    ``distance_m`` [m], ``speed_mps`` [m/s], ``gradient_pct`` [%]; speed and gradient of a sample
    are those in force at the middle of its second.

    Row i's target speed holds from its distance to the next row's; a stop row (v = 0) stands for
    ``stop_time_s`` and then drives on at the next moving row's speed; the last row is the end. Speeds
    change in steps, as targets do (a driver model, as in the simulation, smooths them).
    """
    s = vdri["distance_m"].to_numpy(float)
    v = vdri["target_speed_mps"].to_numpy(float)
    grad = vdri["gradient_pct"].to_numpy(float)
    stop = vdri["stop_time_s"].to_numpy(float)
    if len(s) < 2:
        raise CycleFileError("a VECTO cycle needs at least two rows")
    pieces = []  # (start time [s], duration [s], start distance [m], speed [m/s], gradient [%])
    clock = 0.0
    for i in range(len(s) - 1):
        if v[i] <= 0:
            if stop[i] > 0:
                pieces.append((clock, stop[i], s[i], 0.0, grad[i]))
                clock += stop[i]
            ahead = np.flatnonzero(v[i + 1:] > 0)
            speed = v[i + 1 + ahead[0]] if ahead.size else 0.0
        else:
            speed = v[i]
        length = s[i + 1] - s[i]
        if length > 0:
            if speed <= 0:
                raise CycleFileError(f"VECTO cycle row {i + 2}: distance advances with target speed 0")
            pieces.append((clock, length / speed, s[i], speed, grad[i]))
            clock += length / speed
    if v[-1] <= 0 and stop[-1] > 0:
        pieces.append((clock, stop[-1], s[-1], 0.0, grad[-1]))
        clock += stop[-1]
    pieces.append((clock, 0.0, s[-1], v[-1], grad[-1]))
    table = np.array(pieces)
    time = np.arange(0.0, np.round(clock) + 1.0)
    which = np.clip(np.searchsorted(table[:, 0], time + 0.5, side="right") - 1, 0, len(table) - 1)
    speed = table[which, 3]
    at = np.clip(np.searchsorted(table[:, 0], time, side="right") - 1, 0, len(table) - 1)
    distance = table[at, 2] + table[at, 3] * np.clip(time - table[at, 0], 0.0, table[at, 1])
    return pd.DataFrame({"time_s": time, "distance_m": distance, "speed_mps": speed,
                         "gradient_pct": table[which, 4]})
