"""A group's measured wheel loads as the refined cycle selection's target, from its additive
statistics alone (`FleetStatistics`): the same load criteria `markov.load_criteria` takes from one
drive's signals, so a fleet's cycle is selected as `analyze run` selects a drive's.

From the sums: wheel energy per km (energy totals over the loads' distance), damage-equivalent
torque ranges (the Palmgren–Miner sums), wheel power exceeded 5/50/95 % of the time (the fine
power histogram, `LoadBins.power_level_w`, linear within its bins: off by less than a bin) and the
speed × torque residence shares on the histogram's own fixed bins.
"""

from __future__ import annotations

import numpy as np

from ..markov.chain import Chain
from ..markov.load_criteria import EXPONENTS, POWER_SHARES, LoadTarget, target_of
from ..vehicle import Vehicle
from .histograms import SparseHistogram
from .statistics import FleetStatistics


def time_quantile(histogram: SparseHistogram, share: float) -> float:
    """Level below which the time ``share`` is spent, linear within the bin it falls in."""
    width = histogram.widths[0]
    times = histogram.values
    cumulative = np.cumsum(times)
    if len(times) == 0 or cumulative[-1] <= 0:
        return float("nan")
    goal = share * cumulative[-1]
    i = int(min(np.searchsorted(cumulative, goal), len(times) - 1))
    before = cumulative[i] - times[i]
    within = (goal - before) / times[i] if times[i] > 0 else 0.0
    return float((histogram.keys[i, 0] + within) * width)


def residence_share(histogram: SparseHistogram) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time shares of the speed × torque histogram on a dense grid of its occupied span, and the
    grid's speed [rpm] and torque [Nm] edges."""
    low, high = histogram.keys.min(axis=0), histogram.keys.max(axis=0)
    grid = np.zeros(tuple(high - low + 1))
    grid[tuple((histogram.keys - low).T)] = histogram.values
    edges = [(low[a] + np.arange(grid.shape[a] + 1)) * histogram.widths[a] for a in range(2)]
    return grid / grid.sum(), edges[0], edges[1]


def load_target_of(statistics: FleetStatistics, vehicle: Vehicle, chain: Chain) -> LoadTarget | None:
    """The load target of a group's summed statistics; None when no log had wheel loads."""
    totals = statistics.totals
    residence = statistics.histograms["residence_speed_torque_s"]
    km = totals.get("loads_distance_km", 0.0)
    if totals["loads_s"] <= 0 or km <= 0 or residence.total <= 0:
        return None
    damage = statistics.damage_equivalent_torque_nm()
    power = statistics.histograms["wheel_power_levels_s"]
    values = np.array([totals["positive_wheel_energy_kwh"] / km, totals["negative_wheel_energy_kwh"] / km]
                      + [damage[k] for k in EXPONENTS] + [time_quantile(power, s) for s in POWER_SHARES] + [0.0])
    share, speed_edges, torque_edges = residence_share(residence)
    torque = statistics.histograms["time_at_level_wheel_torque_nm"]
    span = float((torque.keys.max() - torque.keys.min() + 1) * torque.widths[0]) if torque.total > 0 else 1.0
    return target_of(values, share, speed_edges, torque_edges, span, vehicle, chain)
