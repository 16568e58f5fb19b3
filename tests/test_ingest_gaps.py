"""Silences between logs are shortened, not materialised row by row (memory grows with recorded time)."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from haulprofile.analysis.ingest import align, ingest_logs
from haulprofile.testing import logs as synthetic

DAY_NS = 86_400 * 10**9


def _write(path, seconds, seed, t0, realtime_offset=synthetic.REALTIME_OFFSET_NS):
    with open(path, "wb") as stream:
        return synthetic.write_log(stream, seconds, seed=seed, t0_mono_ns=t0, realtime_offset_ns=realtime_offset)


def test_two_logs_a_day_apart_make_recorded_rows_not_a_day_of_rows(tmp_path):
    """Two 10 s logs one day apart: 10 s + 60 s of gap rows + 10 s, not 864 200 rows; said in a warning."""
    t0 = synthetic.T0_MONO_NS
    _write(tmp_path / "a.mcap", 10, 1, t0)
    _write(tmp_path / "b.mcap", 10, 2, t0 + DAY_NS)
    warnings = []
    frame, summary = ingest_logs([tmp_path], say=warnings.append)
    kept = int(align.KEPT_GAP_S * 10)
    assert len(frame) == 100 + kept + 100
    assert frame["valid"].sum() == 200 and not frame["valid"].iloc[100:100 + kept].any()
    assert np.all(np.diff(frame["time_s"]) > 0)
    wall = frame["wall_time_ns"].to_numpy()
    assert wall[100 + kept] - wall[99] == pytest.approx(DAY_NS - 9.9e9, abs=2e8)
    assert summary["span_s"] == pytest.approx(86_410, abs=0.2)
    (gap,) = summary["gaps_shortened"]
    assert gap["row"] == 100 + kept and gap["removed_s"] == pytest.approx(86_400 - 10 - align.KEPT_GAP_S, abs=0.2)
    assert any("shortened" in w for w in warnings)


def test_a_silence_shorter_than_the_limit_stays_row_by_row():
    acc = align.BinAccumulator(10.0)
    time_ns = np.concatenate([np.arange(0, 20), np.arange(20 + 3000, 3030)]) * 100_000_000
    acc.mark_recorded(time_ns)
    grid = acc.grid()
    assert grid.n == 3030 and len(grid.run_bins) == 1


def test_grid_maps_bins_to_rows_and_back():
    acc = align.BinAccumulator(10.0)
    bins = np.concatenate([np.arange(5, 15), np.arange(100_000, 100_010)])
    acc.mark_recorded(bins * 100_000_000)
    acc.add("x", bins * 100_000_000, bins.astype(float))
    grid = acc.grid(max_gap_s=60.0, kept_gap_s=2.0)
    assert grid.n == 10 + 20 + 10
    assert np.array_equal(grid.rows_of(np.array([5, 14, 15, 34, 35, 100_000, 4, 100_010])),
                          [0, 9, 10, 29, -1, 30, -1, -1])
    assert np.array_equal(grid.bins()[grid.rows_of(bins)], bins)
    series = acc.series("x", grid)
    assert np.array_equal(series[grid.rows_of(bins)], bins) and np.isnan(series[10:30]).all()
    recorded = acc.recorded(grid)
    assert recorded.sum() == 20 and not recorded[10:30].any()


def test_logs_months_apart_run_under_a_memory_limit(tmp_path):
    """``analyze info`` on two logs 90 days apart, in a process limited to 1.5 GB of address space."""
    t0 = synthetic.T0_MONO_NS
    _write(tmp_path / "a.mcap", 5, 1, t0)
    _write(tmp_path / "b.mcap", 5, 2, t0 + 90 * DAY_NS)
    script = textwrap.dedent(f"""
        import resource, sys
        from haulprofile.analysis import cli
        import numba, pandas, pyarrow  # their start-up mappings before the limit
        mapped = int(open("/proc/self/statm").read().split()[0]) * resource.getpagesize()
        limit = mapped + 1_500_000_000
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        sys.exit(cli.main(["info", {str(tmp_path)!r}]))
    """)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert result.returncode == 0, result.stderr
    assert "shortened" in result.stderr + result.stdout
