"""The distance grid: samples binned by driven distance, and a weighted local-linear smoother.

Gradient is the derivative of height over *distance* (5); binning samples by wheel distance first
means standstill (many samples, ds = 0) becomes one bin instead of a division by zero.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import correlate1d


def grid_index(distance_m: np.ndarray, spacing_m: float) -> np.ndarray:
    """Index of the nearest grid point s_i = i * spacing for each sample (-1 where distance is NaN)."""
    distance = np.asarray(distance_m, dtype=float)
    index = np.full(distance.shape, -1, dtype=np.int64)
    ok = np.isfinite(distance)
    index[ok] = np.rint(distance[ok] / spacing_m).astype(np.int64)
    return index


def bin_mean(index: np.ndarray, values: np.ndarray, n_bins: int) -> np.ndarray:
    """Mean of the finite ``values`` falling into each grid bin (NaN for an empty bin)."""
    values = np.asarray(values, dtype=float)
    ok = (index >= 0) & np.isfinite(values)
    total = np.bincount(index[ok], weights=values[ok], minlength=n_bins)[:n_bins]
    count = np.bincount(index[ok], minlength=n_bins)[:n_bins]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def local_linear(values: np.ndarray, weights: np.ndarray, spacing_m: float, sigma_m: float):
    """Gaussian-weighted local-linear fit around every grid point.

    Returns (level [unit of values], slope [unit per m], support [0..1]): the fitted value and
    derivative at each point, and the weight fraction of the kernel backed by data. A profile that
    is linear within the kernel is reproduced exactly, including at one-sided edges (tunnel
    portals, gaps), which a moving average then difference is not. NaN where support < 2 %.
    """
    values = np.asarray(values, dtype=float)
    weight = np.where(np.isfinite(values), np.nan_to_num(np.asarray(weights, dtype=float)), 0.0)
    data = np.where(weight > 0, values, 0.0)
    half = max(1, int(np.ceil(3 * sigma_m / spacing_m)))
    offset_m = np.arange(-half, half + 1) * spacing_m
    kernel = np.exp(-0.5 * (offset_m / sigma_m) ** 2)

    def corr(x, k):
        return correlate1d(x, k, mode="constant", cval=0.0)

    s0, s1, s2 = corr(weight, kernel), corr(weight, kernel * offset_m), corr(weight, kernel * offset_m ** 2)
    t0, t1 = corr(weight * data, kernel), corr(weight * data, kernel * offset_m)
    support = s0 / kernel.sum()
    det = s0 * s2 - s1 * s1
    with np.errstate(invalid="ignore", divide="ignore"):
        well_posed = det > 1e-6 * np.maximum(s0, 1e-12) ** 2 * sigma_m ** 2
        slope = np.where(well_posed, (s0 * t1 - s1 * t0) / det, np.nan)
        level = np.where(well_posed, (s2 * t0 - s1 * t1) / det, t0 / s0)
    empty = support < 0.02
    level[empty] = np.nan
    slope[empty] = np.nan
    return level, slope, support
