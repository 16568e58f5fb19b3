"""GPS altitude's error in a street canyon: the receiver's stated accuracy above its open-sky level.

A receiver's vertical accuracy (NMEA GST's altitude error, UBX vAcc) is its open-sky level, a few
metres from the atmosphere and the orbits, correlated over tens of seconds, until buildings
reflect and block the signals: then it rises, by the receiver's own judgement of the multipath.
The smoother takes GPS altitude as white noise of three times the stated accuracy (an allowance for
the correlation, `SmootherSettings.gps_sigma_factor`). How much of the rise in a town is really
in the altitude the receiver does not know; GPS altitude's own residual against the profile says
it (`multipath_share`): the excess variance over the open-sky level is scaled by it, the
open-sky part is kept as the receiver states it.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter
from scipy.stats import chi2

OPEN_SKY_WINDOW_M = 600.0
"""Running-median length [m] whose lowest value over a drive is the receiver's open-sky accuracy:
tens of fixes, longer than the stated accuracy's fix-to-fix jitter, shorter than the open
stretches between towns."""
MIN_EXCESS_BINS = 50
"""Fewer grid points with multipath than this (500 m at 10 m spacing) tell no share: the
receiver's accuracy is taken as it is."""
CHI2_MEDIAN_1DOF = float(chi2.median(1))
"""Median of a squared standard normal: a Gaussian error's median square over its variance."""
MIN_ACCURACY_M = 1.0
"""The smoother's floor on a stated accuracy [m] (a fix never knows its altitude better)."""


def open_sky_accuracy_m(v_acc_m: np.ndarray, spacing_m: float) -> float | None:
    """The receiver's open-sky vertical accuracy [m]: the lowest `OPEN_SKY_WINDOW_M` running
    median of the per-bin stated accuracy ``v_acc_m`` (NaN: no fix); None without fixes. A drive
    entirely in a town gives the town's level, so its excess is zero and nothing changes."""
    stated = np.asarray(v_acc_m, dtype=float)
    stated = np.fmax(stated[np.isfinite(stated)], MIN_ACCURACY_M)
    if stated.size == 0:
        return None
    window = max(1, min(int(round(OPEN_SKY_WINDOW_M / spacing_m)), stated.size))
    return float(np.min(median_filter(stated, size=window, mode="nearest")))


def excess_variance_m2(v_acc_m: np.ndarray, open_sky_m: float) -> np.ndarray:
    """Per bin, the stated variance above the open-sky level [m²] (0 at or below it)."""
    stated = np.fmax(np.asarray(v_acc_m, dtype=float), MIN_ACCURACY_M)
    return np.fmax(stated ** 2 - open_sky_m ** 2, 0.0)


def multipath_share(residual_m: np.ndarray, height_var_m2: np.ndarray, v_acc_m: np.ndarray,
                    open_sky_m: float) -> float | None:
    """How much of the receiver's excess variance is in GPS altitude [-]: where the stated
    accuracy is above √2 × the open-sky level (the excess larger than the open-sky variance), the
    median of (ε² + P_hh − s₀²)/excess over that median for a Gaussian error (`CHI2_MEDIAN_1DOF`),
    ε the altitude's residual against the smoothed height, P_hh the height's variance (what the
    residual misses of the error, as in expectation-maximisation) and s₀² the median of ε² + P_hh
    where there is no excess (the open-sky error and the profile's own). The median keeps the
    tunnel portals' and outages' few large residuals from leading. None with fewer than
    `MIN_EXCESS_BINS` such grid points."""
    excess = excess_variance_m2(v_acc_m, open_sky_m)
    square = np.asarray(residual_m, dtype=float) ** 2 + np.asarray(height_var_m2, dtype=float)
    have = np.isfinite(square) & np.isfinite(np.asarray(v_acc_m, dtype=float))
    urban = have & (excess > open_sky_m ** 2)
    open_sky = have & (excess == 0.0)
    if urban.sum() < MIN_EXCESS_BINS or not open_sky.any():
        return None
    baseline = float(np.median(square[open_sky]))
    return max(float(np.median((square[urban] - baseline) / excess[urban])) / CHI2_MEDIAN_1DOF, 0.0)


def altitude_variance_m2(v_acc_m: np.ndarray, factor: float, open_sky_m: float | None = None,
                         share: float = 1.0) -> np.ndarray:
    """The smoother's GPS altitude variance per bin [m²]: (factor × stated accuracy)², with the
    excess over ``open_sky_m`` scaled by ``share`` (1 or no open-sky level: as stated)."""
    stated = np.fmax(np.asarray(v_acc_m, dtype=float), MIN_ACCURACY_M)
    if open_sky_m is None or share == 1.0:
        return (factor * stated) ** 2
    open_part = np.fmin(stated, open_sky_m) ** 2
    return factor ** 2 * (open_part + share * excess_variance_m2(stated, open_sky_m))
