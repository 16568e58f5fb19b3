"""`runs.true_runs`: the runs of True in a flag series, end exclusive, in order."""

from __future__ import annotations

import numpy as np

from haulprofile.analysis.runs import true_runs


def test_the_runs_of_a_flag_series_with_runs_at_both_ends():
    flags = np.array([True, True, False, True, False, False, True])
    assert true_runs(flags) == [(0, 2), (3, 4), (6, 7)]
    assert true_runs(np.zeros(4, bool)) == [] and true_runs(np.ones(3, bool)) == [(0, 3)]
    assert true_runs(np.array([], bool)) == []
