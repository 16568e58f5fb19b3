"""The height and gradient sources of equations (6)-(8), per sample, before gridding."""

from __future__ import annotations

import numba
import numpy as np

from ..road_load import G_MPS2
from ..runs import true_runs

SEA_LEVEL_PRESSURE_PA = 101325.0
WEIGHT_BARO = 0.7
"""w_baro of (8), constant as in the paper."""
H_ACC_LIMIT_M = 10.0
V_ACC_LIMIT_M = 15.0


def barometric_height_m(pressure_pa, reference_pressure_pa: float = SEA_LEVEL_PRESSURE_PA):
    """(6): h = 44330.8 m (1 - (p/p0)^(1/5.255)) [m]."""
    return 44330.8 * (1.0 - (np.asarray(pressure_pa, dtype=float) / reference_pressure_pa) ** (1 / 5.255))


def standard_temperature_k(height_m):
    """Temperature of the standard atmosphere behind (6) [K]: 288.15 K - 6.5 K/km."""
    return 288.15 - 0.0065 * np.asarray(height_m, dtype=float)


def map_weight(h_acc_m, v_acc_m, h_limit_m: float = H_ACC_LIMIT_M, v_limit_m: float = V_ACC_LIMIT_M):
    """w_map of (8) from the GPS accuracies [m]: clip(1 - max(h_acc/h_lim, v_acc/v_lim), 0, 1);
    0 where an accuracy is unknown (NaN)."""
    ratio = np.maximum(np.asarray(h_acc_m, dtype=float) / h_limit_m, np.asarray(v_acc_m, dtype=float) / v_limit_m)
    return np.where(np.isfinite(ratio), np.clip(1.0 - ratio, 0.0, 1.0), 0.0)


def imu_sin_angle(accel_imu_mps2, accel_mps2):
    """(7): sin(alpha) = (a_imu - dv/dt) / g, clipped to [-1, 1]."""
    return np.clip((np.asarray(accel_imu_mps2, dtype=float) - np.asarray(accel_mps2, dtype=float)) / G_MPS2, -1, 1)


def imu_excess_mps2(accel_imu_mps2, accel_mps2, time_s, window_s: float = 1.0):
    """a_imu - dv/dt [m/s²] (= g sin(alpha) + bias, (7)), with a_imu through the same centred
    moving mean that made dv/dt from wheel speed, so both describe the same moment."""
    time_s = np.asarray(time_s, dtype=float)
    steps = np.diff(time_s)
    dt = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 1.0
    window = max(1, int(round(window_s / dt)))
    kernel = np.ones(window)
    accel_imu = np.asarray(accel_imu_mps2, dtype=float)
    finite = np.isfinite(accel_imu)
    with np.errstate(invalid="ignore", divide="ignore"):
        smooth = (np.convolve(np.where(finite, accel_imu, 0.0), kernel, "same")
                  / np.convolve(finite.astype(float), kernel, "same"))
    return np.where(finite, smooth, np.nan) - np.asarray(accel_mps2, dtype=float)


def standstill_bias_changes(time_s, speed_mps, specific_force_mps2, stop_speed_mps: float = 0.3,
                            edge_s: float = 20.0, settle_s: float = 2.0) -> list[tuple[int, float, float]]:
    """How far the accelerometer's bias moved over each standstill, as the log shows it: standing,
    the truck neither accelerates nor moves along the road, so its specific force along x is
    g sin(alpha) + bias with alpha fixed, and what changes between a standstill's first and last
    ``edge_s`` (medians, ``settle_s`` after stopping and before starting left out) is the bias,
    moved by the cab's temperature (an IMU warming up or cooling down) or a tractor tilted by what
    was coupled or loaded. Per standstill long enough to tell: (its first sample's index, the
    change [m/s²], the variance of that change from the samples' robust spread [m²/s⁴])."""
    time_s = np.asarray(time_s, dtype=float)
    force = np.asarray(specific_force_mps2, dtype=float)
    standing = ~(np.nan_to_num(np.asarray(speed_mps, dtype=float), nan=np.inf) > stop_speed_mps)
    out = []
    for start, end in true_runs(standing):
        t, f = time_s[start:end], force[start:end]
        edge = min(edge_s, (t[-1] - t[0] - 2 * settle_s) / 2)
        if not edge > 0:
            continue
        first = f[(t >= t[0] + settle_s) & (t < t[0] + settle_s + edge)]
        last = f[(t > t[-1] - settle_s - edge) & (t <= t[-1] - settle_s)]
        first, last = first[np.isfinite(first)], last[np.isfinite(last)]
        if len(first) < 5 or len(last) < 5:
            continue
        spread = 1.4826 * np.median(np.abs(np.concatenate([first - np.median(first), last - np.median(last)])))
        variance = np.pi / 2 * spread ** 2 * (1 / len(first) + 1 / len(last))
        out.append((start, float(np.median(last) - np.median(first)), float(variance)))
    return out


def stuck_to_nan(values, run_samples: int):
    """NaN for runs of at least ``run_samples`` bit-identical values (a sensor that stopped but
    whose last reading was carried forward); a live barometer never repeats itself that long."""
    values = np.asarray(values, dtype=float).copy()
    if len(values) == 0:
        return values
    change = np.concatenate([[True], values[1:] != values[:-1]])
    run_id = np.cumsum(change)
    run_length = np.bincount(run_id)[run_id]
    values[run_length >= run_samples] = np.nan
    return values


def freeze_at_standstill(height_m, speed_mps, time_s, stop_speed_mps: float = 0.3, window_s: float = 2.0):
    """Barometric height [m] with whatever it did while the truck stood removed.

    The road cannot rise under a standing truck, but weather drift (about 1 hPa/h, 8 m/h) and
    door/ventilation pressure steps accumulate there into a single distance bin, which would
    become a gradient spike. Each standstill's change of the ``window_s`` moving mean is
    subtracted from everything after it; samples at standstill become NaN.
    """
    height = np.asarray(height_m, dtype=float)
    stopped = ~(np.nan_to_num(np.asarray(speed_mps, dtype=float), nan=np.inf) > stop_speed_mps)
    if not stopped.any() or stopped.all():
        return np.where(stopped, np.nan, height)
    steps = np.diff(time_s)
    dt = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 1.0
    window = max(1, int(round(window_s / dt)))
    kernel = np.ones(window)
    finite = np.isfinite(height)
    with np.errstate(invalid="ignore", divide="ignore"):
        smooth = (np.convolve(np.where(finite & ~stopped, height, 0.0), kernel, "same")
                  / np.convolve((finite & ~stopped).astype(float), kernel, "same"))
    jumps = np.zeros(len(height))
    for start, end in true_runs(stopped):
        if start == 0 or end >= len(height):
            continue
        before, after = smooth[start - 1], smooth[end]
        if np.isfinite(before) and np.isfinite(after):
            jumps[end] = after - before
    return np.where(stopped, np.nan, height - np.cumsum(jumps))


def _gps_outliers_reference(east_m, north_m, distance_m, time_s, tolerance_m, reacquire_s):
    bad = np.zeros(len(east_m), dtype=np.bool_)
    last = -1
    for k in range(len(east_m)):
        if not (np.isfinite(east_m[k]) and np.isfinite(north_m[k])):
            bad[k] = True
            continue
        if last < 0:
            last = k
            continue
        chord = np.hypot(east_m[k] - east_m[last], north_m[k] - north_m[last])
        driven = abs(distance_m[k] - distance_m[last])
        if chord > driven + tolerance_m + 0.05 * driven and time_s[k] - time_s[last] < reacquire_s:
            bad[k] = True
        else:
            last = k
    return bad


gps_outliers = numba.njit(cache=True)(_gps_outliers_reference)
gps_outliers.__doc__ = """Fixes that jumped: farther from the last good fix than the wheel says the truck drove
(plus ``tolerance_m`` [m] and 5 %). After ``reacquire_s`` [s] without a good fix the next fix
is accepted as the new reference. NaN fixes count as bad. (numba kernel;
``_gps_outliers_reference`` is the same loop in plain Python.)"""
