"""The mass column at stops: a per-segment mass estimate leaves the slow samples around a stop and
the stop itself without a mass; the truck stood there with the mass it arrived with."""

from __future__ import annotations

import numpy as np
import pandas as pd

from . import kinematics
from .runs import equal_runs


def mass_at_stops(time_s: np.ndarray, speed_mps: np.ndarray, mass_kg: np.ndarray,
                  standing_mps: float = 0.1) -> np.ndarray:
    """Mass with the gaps a per-segment mass estimator leaves around stops filled: a driving run
    (between two stops) with some mass takes its median where it has none (slow samples at
    departure and arrival), and a stop takes the mass of the run before it (the truck arrived with
    it), or of the run after it when the one before has none. A driving run without any mass
    stays a gap. A logger's short dropout inside a stop is part of the stop (`kinematics.standing`)."""
    mass = np.array(mass_kg, dtype=float)
    standing = kinematics.standing(time_s, speed_mps, standing_mps)
    starts, ends = equal_runs(standing)
    for a, b in zip(starts, ends):
        run = mass[a:b]
        if not standing[a] and np.isnan(run).any() and not np.isnan(run).all():
            run[np.isnan(run)] = np.nanmedian(run)
    for a, b in zip(starts, ends):
        run = mass[a:b]
        if standing[a] and np.isnan(run).any():
            known = mass[a - 1] if a > 0 else np.nan
            run[np.isnan(run)] = mass[b] if np.isnan(known) and b < len(mass) else known
    return mass


def with_mass_at_stops(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with the mass missing at its stops filled (`mass_at_stops`): the drive as the chain
    counts it, so loads compared with a generated cycle, which stands at its stops, count the
    measured stops too (docs/cycles.md, "Stops in the load target")."""
    if "mass_kg" not in frame.columns or not len(frame):
        return frame
    return frame.assign(mass_kg=mass_at_stops(frame["time_s"].to_numpy(float), frame["speed_mps"].to_numpy(float),
                                              frame["mass_kg"].to_numpy(float)))
