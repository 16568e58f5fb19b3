"""The one-pass binning kernels give exactly (bit for bit) what the sorting path gives."""

import numpy as np
import pytest

from haulprofile.analysis.ingest import align, bin_kernels

PERIOD_NS = 100_000_000


def _samples(rng, n: int, in_order: bool):
    time_ns = np.sort(rng.integers(0, 40 * PERIOD_NS, n)).astype(np.int64)
    if not in_order:
        swap = rng.integers(0, n - 1, max(1, n // 50))
        time_ns[swap], time_ns[swap + 1] = time_ns[swap + 1], time_ns[swap].copy()
    values = rng.standard_normal(n) * 1e3
    values[rng.random(n) < 0.05] = np.nan
    values[rng.random(n) < 0.01] = np.inf
    return time_ns, values


@pytest.mark.parametrize("kind", ["mean", "last"])
@pytest.mark.parametrize("in_order", [True, False])
def test_accumulated_streams_equal_the_sorting_path(kind, in_order):
    rng = np.random.default_rng(7)
    fast, reference = align.BinAccumulator(10.0), align.BinAccumulator(10.0)
    for _ in range(5):
        time_ns, values = _samples(rng, 3000, in_order)
        fast.add("x", time_ns, values, kind)
        args = align.bin_sorting(time_ns, values, PERIOD_NS, kind)
        reference.add_binned("x", args[0], args[1], args[2], int(args[3]), int(args[4]), int(args[5]), kind)
    grid = align.Grid.uniform(0, 400)
    np.testing.assert_array_equal(fast.series("x", grid), reference.series("x", grid))
    assert (fast.streams["x"].n, fast.streams["x"].t_first, fast.streams["x"].t_last) == \
        (reference.streams["x"].n, reference.streams["x"].t_first, reference.streams["x"].t_last)


@pytest.mark.parametrize("compiled", [True, False])
def test_three_axes_equal_one_axis_at_a_time(compiled):
    kernels = (bin_kernels.bin_axes_in_order, bin_kernels.bin_in_order)
    if not compiled:
        kernels = tuple(k.py_func for k in kernels)
    both, single = kernels
    rng = np.random.default_rng(8)
    time_ns = np.sort(rng.integers(0, 50 * PERIOD_NS, 5000)).astype(np.int64)
    raw = rng.integers(-32768, 32767, (5000, 3)).astype(np.int16)
    scale = 9.80665 * 0.061e-3
    in_order, bins, sums, counts, t0, t1 = both(time_ns, raw, scale, PERIOD_NS)
    assert in_order
    for axis in range(3):
        _, bins_1, sums_1, counts_1, _, t0_1, t1_1 = single(time_ns, raw[:, axis].astype(np.float64) * scale,
                                                             PERIOD_NS, False)
        np.testing.assert_array_equal(bins, bins_1)
        np.testing.assert_array_equal(sums[:, axis], sums_1)
        np.testing.assert_array_equal(counts, counts_1)
        assert (t0, t1) == (t0_1, t1_1)
    backwards = time_ns[::-1].copy()
    assert not both(backwards, raw, scale, PERIOD_NS)[0]
    assert not single(backwards, raw[:, 0].astype(np.float64), PERIOD_NS, False)[0]


def test_recorded_bins_equal_numpy_unique():
    rng = np.random.default_rng(9)
    time_ns = np.sort(rng.integers(0, 1000 * PERIOD_NS, 20000)).astype(np.int64)
    for times in (time_ns, np.concatenate([time_ns[5000:], time_ns[:5000]])):
        runs, ascending = bin_kernels.bin_runs(times, PERIOD_NS)
        assert ascending == bool(np.all(np.diff(times) >= 0))
        np.testing.assert_array_equal(runs if ascending else np.unique(runs), np.unique(times // PERIOD_NS))
