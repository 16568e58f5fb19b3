"""Load collectives at the wheel for the measured drive and the generated cycle.

Public: `wheel_loads`, `collectives_of`, `compare`, `stage`; the building blocks live in
`analysis.loads.collectives`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..signals import missing_for
from ..vehicle import Vehicle
from .collectives import wheel_loads
from .summary import Collectives, compare, compute, shared_edges, summary

__all__ = ["Collectives", "NEEDED", "collectives_of", "compare", "stage", "wheel_loads"]

NEEDED = ["time_s", "speed_mps", "accel_mps2", "gradient_pct", "mass_kg"]
"""Columns a drive needs for its wheel loads."""


def loads_of(frame: pd.DataFrame, vehicle: Vehicle) -> pd.DataFrame:
    """Wheel loads of a drive with the `NEEDED` columns (rows with a gap are left out)."""
    valid = frame["valid"].to_numpy(bool) if "valid" in frame.columns else None
    return wheel_loads(frame["time_s"], frame["speed_mps"], frame["accel_mps2"], frame["gradient_pct"],
                       frame["mass_kg"], vehicle, valid=valid)


def median_step_s(frame: pd.DataFrame) -> float:
    """Median sample interval of a drive [s]."""
    steps = np.diff(frame["time_s"].to_numpy(float))
    return float(np.median(steps)) if len(steps) else 0.0


def resample_mean(frame: pd.DataFrame, period_s: float) -> pd.DataFrame:
    """A drive as means over consecutive windows of ``period_s`` [s] (a window with any invalid
    sample is invalid), so drives logged at different rates count cycles on the same time base."""
    columns = [c for c in NEEDED if c in frame.columns]
    window = np.floor((frame["time_s"].to_numpy(float) - float(frame["time_s"].iloc[0])) / period_s + 1e-9)
    grouped = frame[columns].groupby(window)
    out = grouped.mean()
    if "valid" in frame.columns:
        out["valid"] = frame["valid"].astype(bool).groupby(window).all()
    out["time_s"] = float(frame["time_s"].iloc[0]) + out.index.to_numpy(float) * period_s
    return out.reset_index(drop=True)


def collectives_of(drives: dict[str, pd.DataFrame], vehicle: Vehicle,
                   common_rate: bool = True) -> dict[str, Collectives]:
    """Collectives of each named drive, on bins shared by all of them; with ``common_rate`` every
    drive is first averaged onto the coarsest drive's sample interval [choice: rainflow and level
    crossings depend on the sampling rate, so only equal rates compare]."""
    if common_rate and len(drives) > 1:
        period = max(median_step_s(frame) for frame in drives.values())
        drives = {name: (resample_mean(frame, period) if median_step_s(frame) < 0.99 * period else frame)
                  for name, frame in drives.items()}
    loads = {name: loads_of(frame, vehicle) for name, frame in drives.items()}
    edges = shared_edges(*loads.values())
    return {name: compute(load, name, edges) for name, load in loads.items()}


def write_all(collectives: dict[str, Collectives], out_dir: Path) -> tuple[dict, pd.DataFrame | None]:
    """CSVs, figures and the comparison (when both drives are there); returns (summary, comparison)."""
    from .output import write_csvs, write_figures

    out_dir.mkdir(parents=True, exist_ok=True)
    result = {name: summary(c) for name, c in collectives.items()}
    for c in collectives.values():
        write_csvs(c, out_dir)
    comparison = None
    if {"measured", "generated"} <= set(collectives):
        comparison = compare(collectives["measured"], collectives["generated"])
        comparison.to_csv(out_dir / "comparison.csv", index=False)
        result["comparison"] = {row.criterion: (float(row.relative_deviation) if np.isfinite(row.relative_deviation)
                                                else None) for row in comparison.itertuples()}
    write_figures(list(collectives.values()), comparison, out_dir)
    return result, comparison


def stage(ctx) -> None:
    """Pipeline stage: collectives of the measured drive and, if the cycle stage wrote
    ``cycle.csv``, of the generated cycle, into ``loads/``; summary under ``loads``."""
    missing = missing_for(ctx.signals, NEEDED) if ctx.signals is not None else NEEDED
    if missing:
        ctx.say(f"loads: skipped, the signals lack {', '.join(missing)}")
        return
    if ctx.vehicle is None:
        ctx.say("loads: skipped, no vehicle file")
        return
    drives = {"measured": ctx.signals}
    cycle_csv = ctx.out_dir / "cycle.csv"
    if cycle_csv.is_file():
        cycle = pd.read_csv(cycle_csv)
        lacking = missing_for(cycle, NEEDED)
        if lacking:
            ctx.say(f"loads: cycle.csv lacks {', '.join(lacking)}; only the measured drive is counted")
        else:
            drives["generated"] = cycle
    result, _ = write_all(collectives_of(drives, ctx.vehicle), ctx.out_dir / "loads")
    ctx.summary["loads"] = result
    for name, s in result.items():
        if name != "comparison":
            ctx.say(f"loads: {name}: {s['rainflow_cycles']:.0f} rainflow cycles, damage-equivalent torque range "
                    f"(k=5) {s['damage_equivalent_torque_range_nm']['5']:.0f} Nm")
