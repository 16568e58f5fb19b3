"""The wheel odometer's scale against the GPS track.

``distance_m`` is integrated wheel speed (`kinematics`), whose scale is the tyres' rolling
circumference as the logger's speed signal assumes it: tyre wear (15-20 mm of tread on a
500 mm radius), pressure and load move it by a few per cent. Heights binned by that distance are
each the one at the fix's true place, so their gradient is the true one over (1 + ε), ε the
odometer's relative scale error: a share of the gradient itself, one sign over the whole drive,
larger on the climbs where a mass fitted on the gradient leans hardest. Speed, acceleration and
distance are all the wheel's times (1 + ε): the kinematics stage divides them once, for every stage
after it, where the track tells ε (`kinematics.add_kinematics`).

The GPS track measures ε: over 1 s between fixes the chord is the path within millimetres, and its
noise (the receiver's position error changes little within a second under open sky) adds ~0.01 %
to the length. Multipath in towns makes the steps jitter by metres and the track too long (on the
matrix's `harsh` long-haul drive seed 3: 1.51 % with every fix against 1.96 % open-sky and 2.09 %
true), so only steps between two fixes whose stated accuracy is within √2 of the receiver's
open-sky level are summed (`gradient.gps_altitude`'s threshold of multipath).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

from .geodesy import step_lengths_m

MAX_STEP_S = 1.5
"""Longest time [s] between two fixes whose step is summed: longer chords cut the curves."""
MIN_STEP_S = 0.9
"""Shortest: a faster receiver's fixes are taken about a second apart, since the positions' noise
lengthens a step by its variance over twice the step (white 1.5 m at 10 Hz: the track reads
46 % long on 2 m steps, 0.6 % on the 20 m of a second)."""
MAX_SCALE = 0.1
"""Largest |ε| a tyre's circumference makes (wear, pressure and load move it by a few per cent):
beyond it the track does not measure the odometer (a log whose positions jitter), and none is
told."""
MIN_SPEED_MPS = 5.0
"""Slower steps are short against the position's jitter."""
MIN_TRACK_M = 2000.0
"""Less open-sky track than this tells no scale."""
OPEN_SKY_FIXES = 60
"""Running-median length [fixes] whose lowest value is the receiver's open-sky accuracy."""
BLOCK_M = 500.0
"""Track length [m] of the blocks whose scales' scatter gives ε's own σ."""
MIN_BLOCKS = 4
"""Fewer blocks than this tell no σ, and no scale."""
SIGNIFICANCE = 2.0
"""An ε within this many of its σ is not told from 0: a correction smaller than its own
uncertainty moves the estimates by chance (the matrix's `ideal` drives, no scale injected: the
track read −0.11 to +0.05 %)."""


def wheel_distance_scale(frame) -> float | None:
    """ε [-]: ``distance_m`` over the GPS track's length on open-sky steps, less 1 (positive: the
    odometer reads long); None without positions, horizontal accuracy or `MIN_TRACK_M` of track,
    beyond `MAX_SCALE`, or within `SIGNIFICANCE` times its σ (the scatter of its `BLOCK_M` blocks'
    scales, each weighted by its length) of 0.
    A fix is a row whose position or accuracy differs from the row before (a logger holds its last
    fix between them)."""
    needed = {"latitude_deg", "longitude_deg", "gps_h_acc_m", "distance_m", "speed_mps", "time_s"}
    if not needed <= set(frame.columns):
        return None
    lat, lon, h_acc = (frame[c].to_numpy(dtype=float) for c in ("latitude_deg", "longitude_deg", "gps_h_acc_m"))
    time_s, distance, speed = (frame[c].to_numpy(dtype=float) for c in ("time_s", "distance_m", "speed_mps"))
    have = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h_acc) & np.isfinite(distance)
    changed = np.ones(len(lat), bool)
    changed[1:] = (lat[1:] != lat[:-1]) | (lon[1:] != lon[:-1]) | (h_acc[1:] != h_acc[:-1])
    fix = _about_a_second_apart(np.flatnonzero(have & changed), time_s)
    if len(fix) < 3:
        return None
    open_sky = float(np.min(median_filter(h_acc[fix], size=min(OPEN_SKY_FIXES, len(fix)), mode="nearest")))
    step_m = step_lengths_m(lat[fix], lon[fix])
    clear = h_acc[fix] <= np.sqrt(2.0) * open_sky
    fast = speed[fix] > MIN_SPEED_MPS
    ok = ((np.diff(time_s[fix]) <= MAX_STEP_S) & clear[1:] & clear[:-1] & fast[1:] & fast[:-1]
          & np.isfinite(step_m))
    track_m, wheel_m = step_m[ok], np.diff(distance[fix])[ok]
    track = float(np.sum(track_m))
    if track < MIN_TRACK_M:
        return None
    scale = float(np.sum(wheel_m) / track - 1.0)
    block = np.floor(np.cumsum(track_m) / BLOCK_M).astype(np.int64)
    block_track, block_wheel = np.bincount(block, weights=track_m), np.bincount(block, weights=wheel_m)
    full = block_track >= 0.5 * BLOCK_M
    if full.sum() < MIN_BLOCKS:
        return None
    weight = block_track[full] / block_track[full].sum()
    ratios = block_wheel[full] / block_track[full] - 1.0
    sigma = float(np.sqrt(np.sum(weight ** 2 * (ratios - scale) ** 2) * full.sum() / (full.sum() - 1)))
    if abs(scale) > MAX_SCALE or abs(scale) <= SIGNIFICANCE * sigma:
        return None
    return scale


def _about_a_second_apart(fix: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """The fixes (row indices) thinned so that consecutive ones are at least `MIN_STEP_S` apart."""
    kept = []
    last = -np.inf
    for k in fix:
        if time_s[k] - last >= MIN_STEP_S:
            kept.append(k)
            last = time_s[k]
    return np.asarray(kept, dtype=np.int64)

