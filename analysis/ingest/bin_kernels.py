"""Binning in one pass where samples come in time order (they nearly always do: one channel, one
clock), instead of sorting them again: the inner loops of `align.BinAccumulator`.

Each kernel adds in the same order as ``np.bincount`` does (a bin's samples one after the other,
from 0.0), so its sums are bit-identical to the sorting path, which stays for samples out of order.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def bin_in_order(time_ns, values, period_ns, last):
    """Per-bin sums and counts (``last``: the last value) of samples whose finite values come in
    time order; non-finite values are left out.

    Returns (in_order, bins, sums, counts, kept, t_first, t_last); ``in_order`` False (and the
    rest empty) where a kept sample's time runs backwards.
    """
    n = len(values)
    runs = 0
    kept = 0
    previous_t = np.int64(0)
    high = np.int64(0)
    for i in range(n):
        if not np.isfinite(values[i]):
            continue
        t = time_ns[i]
        if kept > 0 and t < previous_t:
            return False, np.zeros(0, np.int64), np.zeros(0), np.zeros(0), 0, np.int64(0), np.int64(0)
        if kept == 0 or t >= high:  # in time order: a new bin only past the current one's end
            high = (t // period_ns + 1) * period_ns
            runs += 1
        previous_t = t
        kept += 1
    bins = np.empty(runs, np.int64)
    sums = np.zeros(runs)
    counts = np.zeros(runs)
    k = -1
    t_first = np.int64(0)
    for i in range(n):
        v = values[i]
        if not np.isfinite(v):
            continue
        t = time_ns[i]
        if k < 0:
            t_first = t
        if k < 0 or t >= high:
            k += 1
            bins[k] = t // period_ns
            high = (bins[k] + 1) * period_ns
        if last:
            sums[k] = v
            counts[k] = 1.0
        else:
            sums[k] += v
            counts[k] += 1.0
    return True, bins, sums, counts, kept, t_first, previous_t


@numba.njit(cache=True, nogil=True)
def bin_runs(time_ns, period_ns):
    """The bin of each run of consecutive samples in one bin (a log's times are nearly sorted: few
    runs), and whether those bins ascend (then they are already the distinct bins, sorted). One
    pass: the runs go into room for one per sample (only the pages written are ever touched)."""
    n = len(time_ns)
    out = np.empty(n, np.int64)
    ascending = True
    k = 0
    low = np.int64(1)
    high = np.int64(0)  # empty: the first sample starts a run
    for i in range(n):
        t = time_ns[i]
        if t < low or t >= high:
            b = t // period_ns
            low = b * period_ns
            high = low + period_ns
            if k > 0 and b < out[k - 1]:
                ascending = False
            out[k] = b
            k += 1
    return out[:k].copy(), ascending


@numba.njit(cache=True, nogil=True)
def bin_axes_in_order(time_ns, raw, scale, period_ns):
    """`bin_in_order` of the three axes of raw sensor counts (``raw``: n × 3) times ``scale`` at
    once: (in_order, bins, sums (runs × 3), counts, t_first, t_last)."""
    n = len(time_ns)
    runs = 0
    high = np.int64(0)
    for i in range(n):
        t = time_ns[i]
        if i > 0 and t < time_ns[i - 1]:
            return False, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), np.int64(0), np.int64(0)
        if i == 0 or t >= high:  # in time order: a new bin only past the current one's end
            high = (t // period_ns + 1) * period_ns
            runs += 1
    bins = np.empty(runs, np.int64)
    sums = np.zeros((runs, 3))
    counts = np.zeros(runs)
    k = -1
    for i in range(n):
        t = time_ns[i]
        if k < 0 or t >= high:
            k += 1
            bins[k] = t // period_ns
            high = (bins[k] + 1) * period_ns
        for axis in range(3):
            sums[k, axis] += np.float64(raw[i, axis]) * scale
        counts[k] += 1.0
    if n == 0:
        return True, bins, sums, counts, np.int64(0), np.int64(0)
    return True, bins, sums, counts, time_ns[0], time_ns[n - 1]
