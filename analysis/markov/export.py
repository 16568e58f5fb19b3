"""The chosen cycle as files (CSV, Parquet, VECTO ``.vdri``), and a VECTO cycle back as a route.

A generated cycle holds one class-centre speed per second. `cycle_to_vdri` writes it as a VECTO
distance-based cycle whose target speed is piecewise constant over distance: row k starts at the
distance reached after k seconds at the speeds before it and holds speed v_k for one second
(consecutive equal rows merged); a standstill run becomes one row with v = 0 and its duration as
``stop_time_s``. Rows are at least 1 m apart, as VECTO requires (see `_metre_steps`). `vecto.vdri_to_time_cycle` reads that back exactly (time, distance, speed, gradient), and
reads any other VECTO cycle as the time trace of its target speeds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import UserError
from ..vecto import COLUMNS as VDRI_COLUMNS, MIN_STEP_M, write_vdri

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
    return pd.DataFrame(_metre_steps(rows), columns=list(VDRI_COLUMNS))


def _metre_steps(rows: list[tuple]) -> list[tuple]:
    """Rows (distance, speed, gradient, stop time; the last marks the end) at least VECTO's 1 m apart.

    Consecutive moving rows are joined until they span 1 m (2 m after a stop, whose next row then
    sits 1 m on: a stop drives on at the next row's speed anyway) into one row of their mean speed
    (distance over time) and distance-weighted gradient, so time and distance stay exact. Creeping
    under that span before a stop or the end joins the row before it (into a stop: the creep's
    time becomes stop time, its distance, under 2 m, is lost).
    """
    step = MIN_STEP_M + 0.01  # the file rounds distances to 1 cm
    out: list[list] = []
    group: list = []  # [start distance, length, time, gradient x length, rows, first row]

    def close() -> None:
        start, length, time, g_len, count, first = group
        if count == 1:
            row = list(first)
        else:
            row = [start, length / time, g_len / length, 0.0]
        if out and out[-1][1] == 0:
            row[0] = start + step
        out.append(row)
        group.clear()

    def fold() -> None:
        """Creep under the minimum span into the row before it."""
        start, length, time, g_len, _count, _first = group
        group.clear()
        if not out:
            out.append([start, 0.0, g_len / length, time])
        elif out[-1][1] == 0:
            out[-1][3] += time
        else:
            begins = out[-2][0] if len(out) > 1 and out[-2][1] == 0 else out[-1][0]  # a stop drives on at its speed
            previous_length = start - begins
            previous_time = previous_length / out[-1][1]
            out[-1][2] = (out[-1][2] * previous_length + g_len) / (previous_length + length)
            out[-1][1] = (previous_length + length) / (previous_time + time)

    for i, row in enumerate(rows[:-1]):
        if row[1] == 0:
            if group:
                fold()
            if out and out[-1][1] == 0:
                out[-1][3] += row[3]
            else:
                out.append(list(row))
            continue
        span = rows[i + 1][0] - row[0]
        if not group:
            group[:] = [row[0], 0.0, 0.0, 0.0, 0, row]
        group[1] += span
        group[2] += span / row[1]
        group[3] += row[2] * span
        group[4] += 1
        need = 2 * step if out and out[-1][1] == 0 else step
        if group[1] >= need:
            close()
    end = list(rows[-1])
    if group:
        fold()
    if out and out[-1][1] == 0 and end[0] - out[-1][0] < step:
        out[-1][3] += end[3]
        return [tuple(r) for r in out]
    return [tuple(r) for r in out] + [tuple(end)]


def write_cycle(cycle: pd.DataFrame, out_dir: str | Path, stem: str = "cycle") -> dict[str, Path]:
    """Write ``<stem>.csv``, ``<stem>.parquet``, ``<stem>.vdri`` and the FASTSim 3 cycle
    ``<stem>.fastsim.csv`` into ``out_dir``."""
    from ..export.fastsim import write_fastsim_cycle  # its package pulls in ingest: not on the selection's path

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    columns = [c for c in CSV_COLUMNS if c in cycle.columns]
    paths = {"csv": out_dir / f"{stem}.csv", "parquet": out_dir / f"{stem}.parquet",
             "vdri": out_dir / f"{stem}.vdri", "fastsim": out_dir / f"{stem}.fastsim.csv"}
    cycle[columns].to_csv(paths["csv"], index=False)
    cycle[columns].to_parquet(paths["parquet"], index=False)
    write_vdri(cycle_to_vdri(cycle), paths["vdri"])
    write_fastsim_cycle(cycle, paths["fastsim"])
    return paths
