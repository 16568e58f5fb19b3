"""Load collectives at the wheel for the measured drive and the generated cycle.

Public: `wheel_loads`, `collectives_of`, `compare`; the building blocks live in
`analysis.loads.collectives`, the pipeline's stage in `analysis.loads.stage`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..kinematics import acceleration_mps2
from ..vehicle import Vehicle
from .collectives import wheel_loads
from .bins import LoadEdges, default_edges
from .summary import Collectives, compare, compute

__all__ = ["Collectives", "NEEDED", "collectives_of", "compare", "wheel_loads"]

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
    sample is invalid), its acceleration estimated from the means' speed, so drives logged at
    different rates count cycles on the same time base."""
    columns = [c for c in NEEDED if c in frame.columns]
    window = np.floor((frame["time_s"].to_numpy(float) - float(frame["time_s"].iloc[0])) / period_s + 1e-9)
    grouped = frame[columns].groupby(window)
    out = grouped.mean()
    out["time_s"] = float(frame["time_s"].iloc[0]) + out.index.to_numpy(float) * period_s
    if "accel_mps2" in out.columns and len(out) > 1:
        # the mean of a faster rate's acceleration keeps cycles shorter than the new step, which a
        # drive logged at that rate and a generated cycle cannot have
        out["accel_mps2"] = acceleration_mps2(out["time_s"].to_numpy(float), out["speed_mps"].to_numpy(float),
                                              window_s=period_s)
    if "valid" in frame.columns:
        out["valid"] = frame["valid"].astype(bool).groupby(window).all()
    return out.reset_index(drop=True)


def collectives_of(drives: dict[str, pd.DataFrame], vehicle: Vehicle,
                   common_rate: bool = True, edges: LoadEdges | None = None) -> dict[str, Collectives]:
    """Collectives of each named drive, on fixed bins (``edges``, by default the vehicle class's,
    `loads.bins`) so any drives sum and compare bin by bin; with ``common_rate`` every
    drive is first averaged onto the coarsest drive's sample interval [choice: rainflow and level
    crossings depend on the sampling rate, so only equal rates compare].

    Parameters
    ----------
    drives : dict of str to DataFrame
        Name → drive with ``time_s`` [s], ``speed_mps`` [m/s], ``accel_mps2`` [m/s²],
        ``gradient_pct`` [%], ``mass_kg`` [kg] (`NEEDED`).
    vehicle : Vehicle
        Wheel radius, driving resistances and rotating masses of the one vehicle model.
    common_rate : bool
        Average every drive onto the coarsest drive's sample interval first.
    edges : LoadEdges, optional
        The bins; `loads.bins.default_edges` of the vehicle when None.

    Returns
    -------
    dict of str to Collectives
        Per drive: time at level of wheel force [N], torque [Nm], speed [rpm] and power [W], the
        speed × torque residence [s], rainflow range/mean counts of the wheel torque, level
        crossings and damage-equivalent torque ranges [Nm].

    References
    ----------
    Wheel force from paper equations (1)-(4); rainflow counting per ASTM E1049.
    """
    if common_rate and len(drives) > 1:
        period = max(median_step_s(frame) for frame in drives.values())
        drives = {name: (resample_mean(frame, period) if median_step_s(frame) < 0.99 * period else frame)
                  for name, frame in drives.items()}
    loads = {name: loads_of(frame, vehicle) for name, frame in drives.items()}
    arrays = (edges or default_edges(vehicle)).arrays()
    return {name: compute(load, name, arrays) for name, load in loads.items()}
