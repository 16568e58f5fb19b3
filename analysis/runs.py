"""Runs of a flag along a series: where a stop, a fuel cut, a brake application or a gap starts and
ends."""

from __future__ import annotations

import numpy as np


def true_runs(flags) -> list[tuple[int, int]]:
    """(start, end) index pairs of the runs of True in ``flags``, end exclusive, in order."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(flags).astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def equal_runs(flags) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) index arrays of the runs of equal values in a boolean array, True
    and False runs alike, in order."""
    flags = np.asarray(flags)
    edges = np.flatnonzero(np.diff(flags.astype(np.int8))) + 1
    return np.concatenate([[0], edges]), np.concatenate([edges, [len(flags)]])


def widened(flags, samples: int) -> np.ndarray:
    """``flags`` with every True spread ``samples`` either side (a margin around brake applications
    or shifts that a centred window would otherwise reach into)."""
    flags = np.asarray(flags, dtype=bool)
    if samples <= 0:
        return flags
    return np.convolve(flags.astype(float), np.ones(2 * samples + 1), "same") > 0
