"""Bilinear interpolation on a height grid that tolerates voids."""

from __future__ import annotations

import numpy as np


def bilinear_m(grid: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Height [m] at fractional (row, col) positions of ``grid``.

    Corner weights of a void (NaN) corner are dropped and the others renormalised, so a single void
    beside a fix does not lose the fix; NaN only when all four corners are voids or the position
    lies outside the grid.
    """
    rows, cols = grid.shape
    row = np.asarray(row, dtype=float)
    col = np.asarray(col, dtype=float)
    inside = (row >= 0) & (row <= rows - 1) & (col >= 0) & (col <= cols - 1)
    r0 = np.clip(np.floor(np.where(inside, row, 0)).astype(np.int64), 0, max(rows - 2, 0))
    c0 = np.clip(np.floor(np.where(inside, col, 0)).astype(np.int64), 0, max(cols - 2, 0))
    fr = np.where(inside, row - r0, 0.0)
    fc = np.where(inside, col - c0, 0.0)
    r1 = np.minimum(r0 + 1, rows - 1)
    c1 = np.minimum(c0 + 1, cols - 1)
    total = np.zeros(row.shape)
    weight = np.zeros(row.shape)
    for rr, cc, w in ((r0, c0, (1 - fr) * (1 - fc)), (r0, c1, (1 - fr) * fc),
                      (r1, c0, fr * (1 - fc)), (r1, c1, fr * fc)):
        value = grid[rr, cc]
        good = np.isfinite(value) & (w > 0)
        total += np.where(good, value * w, 0.0)
        weight += np.where(good, w, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(weight > 1e-9, total / weight, np.nan)
    return np.where(inside, out, np.nan)
