"""Runs of a flag along a series: where a stop, a fuel cut, a brake application or a gap starts and
ends."""

from __future__ import annotations

import numpy as np


def true_runs(flags) -> list[tuple[int, int]]:
    """(start, end) index pairs of the runs of True in ``flags``, end exclusive, in order."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(flags).astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))
