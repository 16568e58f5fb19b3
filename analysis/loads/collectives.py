"""Load collectives at the wheel (physics.md, load section; paper §2.3, end).

Statically at the wheel, with the one vehicle model `analysis.road_load`: time-at-level
histograms, the speed x torque residence-time matrix, rainflow (ASTM E1049, the ``rainflow``
package) range/mean matrices, level crossings and damage-equivalent torques. Everything that is
a count or a time is additive, so collectives of several drives sum.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import rainflow

from .. import road_load
from ..vehicle import Vehicle

RPM_PER_RADPS = 60.0 / (2.0 * np.pi)
WOEHLER_EXPONENTS = tuple(range(3, 11))
"""Wöhler (S-N) slopes k for the damage-equivalent torques [-]."""
EQUIVALENT_FREQUENCY_HZ = 1.0
"""[choice] Damage-equivalent loads are stated for 1 equivalent cycle per second of operation."""
QUANTITIES = {
    "wheel_force_n": "wheel force [N]",
    "wheel_torque_nm": "wheel torque [Nm]",
    "wheel_speed_rpm": "wheel speed [rpm]",
    "wheel_power_w": "wheel power [W]",
}


def sample_durations_s(time_s, valid=None) -> np.ndarray:
    """Time each sample stands for [s]: half the interval to each neighbour (so the durations sum
    to the span of the drive); samples not ``valid`` stand for no time."""
    time = np.asarray(time_s, float)
    if len(time) < 2:
        return np.zeros(len(time))
    edges = np.concatenate([[time[0]], 0.5 * (time[1:] + time[:-1]), [time[-1]]])
    durations = np.diff(edges)
    if valid is not None:
        durations = np.where(np.asarray(valid, bool), durations, 0.0)
    return durations


def wheel_loads(time_s, speed_mps, accel_mps2, gradient_pct, mass_kg, vehicle: Vehicle,
                rotating_mass_kg: float = 0.0, valid=None) -> pd.DataFrame:
    """Wheel force (1) [N], torque [Nm], speed [rpm] and power [W] of a drive, one row per
    sample, with the time each sample stands for (``duration_s``)."""
    speed = np.asarray(speed_mps, float)
    force = np.asarray(road_load.wheel_force_n(speed, accel_mps2, gradient_pct, mass_kg, vehicle,
                                               rotating_mass_kg), float)
    usable = np.isfinite(force) & np.isfinite(speed)
    valid = usable if valid is None else (usable & np.asarray(valid, bool))
    frame = pd.DataFrame({
        "time_s": np.asarray(time_s, float),
        "duration_s": sample_durations_s(time_s, valid),
        "speed_mps": speed,
        "wheel_force_n": force,
        "wheel_torque_nm": force * vehicle.wheel_radius_m,
        "wheel_speed_rpm": np.asarray(road_load.wheel_speed_radps(speed, vehicle.wheel_radius_m)) * RPM_PER_RADPS,
        "wheel_power_w": force * speed,
    })
    return frame[valid].reset_index(drop=True)


def level_edges(*series, n_bins: int = 40) -> np.ndarray:
    """``n_bins`` equal bins spanning every series given (so collectives compare bin by bin)."""
    values = np.concatenate([np.asarray(x, float).ravel() for x in series]) if series else np.empty(0)
    values = values[np.isfinite(values)]
    low, high = (float(values.min()), float(values.max())) if len(values) else (0.0, 1.0)
    if high <= low:
        high = low + 1.0
    return np.linspace(low, high, n_bins + 1)


def time_at_level(values, durations_s, edges) -> np.ndarray:
    """Time spent in each level bin [s]; values beyond the edges count in the end bins, so the
    histogram holds all the time."""
    clipped = np.clip(np.asarray(values, float), edges[0], edges[-1])
    hist, _ = np.histogram(clipped, bins=edges, weights=np.asarray(durations_s, float))
    return hist


def residence_matrix(speed, torque, durations_s, speed_edges, torque_edges) -> np.ndarray:
    """2D residence time [s]: rows speed bins, columns torque bins (ends catch the outliers)."""
    hist, _, _ = np.histogram2d(np.clip(np.asarray(speed, float), speed_edges[0], speed_edges[-1]),
                                np.clip(np.asarray(torque, float), torque_edges[0], torque_edges[-1]),
                                bins=[speed_edges, torque_edges], weights=np.asarray(durations_s, float))
    return hist


def rainflow_cycles(series) -> pd.DataFrame:
    """Rainflow cycles (ASTM E1049, ``rainflow.extract_cycles``): range, mean, count (0.5 or 1)
    and the sample indices where each starts and ends."""
    rows = list(rainflow.extract_cycles(np.asarray(series, float)))
    return pd.DataFrame(rows if rows else np.empty((0, 5)),
                        columns=["range", "mean", "count", "start_index", "end_index"])


def rainflow_matrix(cycles: pd.DataFrame, range_edges, mean_edges) -> np.ndarray:
    """Cycle counts in range x mean bins (ends catch the outliers)."""
    hist, _, _ = np.histogram2d(np.clip(cycles["range"].to_numpy(float), range_edges[0], range_edges[-1]),
                                np.clip(cycles["mean"].to_numpy(float), mean_edges[0], mean_edges[-1]),
                                bins=[range_edges, mean_edges], weights=cycles["count"].to_numpy(float))
    return hist


def level_crossings(series, levels) -> np.ndarray:
    """Upward crossings of each level: the number of steps x[i-1] < level <= x[i]."""
    x = np.asarray(series, float)
    x = x[np.isfinite(x)]
    levels = np.asarray(levels, float)
    if len(x) < 2:
        return np.zeros(len(levels), dtype=np.int64)
    low, high = x[:-1], x[1:]
    rising = high > low
    order = np.argsort(levels)
    sorted_levels = levels[order]
    first = np.searchsorted(sorted_levels, low[rising], side="right")
    last = np.searchsorted(sorted_levels, high[rising], side="right")
    delta = np.zeros(len(levels) + 1, dtype=np.int64)
    np.add.at(delta, first, 1)
    np.add.at(delta, last, -1)
    counts = np.empty(len(levels), dtype=np.int64)
    counts[order] = np.cumsum(delta)[:-1]
    return counts


def damage_equivalent_range(cycles: pd.DataFrame, equivalent_cycles: float,
                            exponents=WOEHLER_EXPONENTS) -> dict[int, float]:
    """Damage-equivalent range per Wöhler exponent k (Palmgren-Miner):
    S_eq = (sum n_i S_i^k / N_eq)^(1/k), the constant range that in N_eq cycles does the same damage."""
    ranges = cycles["range"].to_numpy(float)
    counts = cycles["count"].to_numpy(float)
    if equivalent_cycles <= 0 or len(ranges) == 0:
        return {k: 0.0 for k in exponents}
    scale = ranges.max() if ranges.max() > 0 else 1.0
    return {k: float(scale * (np.sum(counts * (ranges / scale) ** k) / equivalent_cycles) ** (1.0 / k))
            for k in exponents}
