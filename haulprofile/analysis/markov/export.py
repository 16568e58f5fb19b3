"""The chosen cycle as files (CSV, Parquet, VECTO ``.vdri``), and a VECTO cycle back as a route.

A generated cycle holds one class-centre speed per second. `cycle_to_vdri` writes it as a VECTO
distance-based cycle whose target speed is piecewise constant over distance: row k starts at the
distance reached after k seconds at the speeds before it and holds speed v_k for one second
(consecutive equal rows merged); a standstill run becomes one row with v = 0 and its duration as
``stop_time_s``. `vdri_to_time_cycle` reads that back exactly (time, distance, speed, gradient), and
reads any other VECTO cycle as the time trace of its target speeds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import UserError
from ..vecto import COLUMNS as VDRI_COLUMNS, write_vdri

CSV_COLUMNS = ("time_s", "speed_mps", "accel_mps2", "gradient_pct", "mass_kg", "distance_m")


class CycleExportError(UserError):
    pass


def cycle_to_vdri(cycle: pd.DataFrame) -> pd.DataFrame:
    """A 1 Hz cycle (``time_s`` [s], ``speed_mps`` [m/s], ``gradient_pct`` [%]) as VECTO SI columns
    (``distance_m``, ``target_speed_mps``, ``gradient_pct``, ``stop_time_s``); the last row marks
    the cycle's end (sample n−1 at the distance reached after n−1 seconds)."""
    time = cycle["time_s"].to_numpy(float)
    speed = cycle["speed_mps"].to_numpy(float)
    gradient = cycle["gradient_pct"].to_numpy(float)
    if len(time) < 2 or not np.allclose(np.diff(time), 1.0):
        raise CycleExportError("a cycle for VECTO export needs at least two samples at exactly 1 Hz")
    last = len(speed) - 1
    distance = np.concatenate([[0.0], np.cumsum(speed[:-1])])
    rows = []
    k = 0
    while k <= last:
        if speed[k] == 0:
            end = k
            while end < last and speed[end + 1] == 0:
                end += 1
            rows.append((distance[k], 0.0, gradient[k], float(end - k + (end < last))))
            k = end + 1
            continue
        if k < last and rows and rows[-1][1] == speed[k] and rows[-1][2] == gradient[k]:
            k += 1
            continue
        rows.append((distance[k], speed[k], gradient[k], 0.0))
        k += 1
    return pd.DataFrame(rows, columns=list(VDRI_COLUMNS))


def vdri_to_time_cycle(vdri: pd.DataFrame) -> pd.DataFrame:
    """A VECTO cycle (SI columns, `analysis.vecto.read_vdri`) as a 1 Hz time trace: ``time_s`` [s],
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
        raise CycleExportError("a VECTO cycle needs at least two rows")
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
                raise CycleExportError(f"VECTO cycle row {i + 2}: distance advances with target speed 0")
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


def write_cycle(cycle: pd.DataFrame, out_dir: str | Path, stem: str = "cycle") -> dict[str, Path]:
    """Write ``<stem>.csv``, ``<stem>.parquet`` and ``<stem>.vdri`` into ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    columns = [c for c in CSV_COLUMNS if c in cycle.columns]
    paths = {"csv": out_dir / f"{stem}.csv", "parquet": out_dir / f"{stem}.parquet",
             "vdri": out_dir / f"{stem}.vdri"}
    cycle[columns].to_csv(paths["csv"], index=False)
    cycle[columns].to_parquet(paths["parquet"], index=False)
    write_vdri(cycle_to_vdri(cycle), paths["vdri"])
    return paths
