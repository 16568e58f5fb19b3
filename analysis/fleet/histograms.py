"""Histograms on fixed bin widths, stored sparsely and additive.

Bin ``k`` of an axis of width ``w`` holds ``k·w ≤ x < (k+1)·w``: the bins depend on the width
alone, never on the data, so the histograms of any number of logs add bin by bin, in any grouping,
and only bins that hold something are stored. (``analysis.loads`` spans its bins over the drives of
one call, which is right for one comparison and not additive across calls.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..errors import UserError


@dataclass
class SparseHistogram:
    """``values[i]`` in the bin with indices ``keys[i]`` (one column per axis), rows sorted."""

    axes: tuple[str, ...]
    widths: tuple[float, ...]
    keys: np.ndarray
    values: np.ndarray

    @classmethod
    def of(cls, columns: dict[str, np.ndarray], widths: dict[str, float], weights=None) -> "SparseHistogram":
        """Histogram of the samples (rows) of ``columns`` [their units], each row weighted by
        ``weights`` (a duration [s], a cycle count; 1 when None); rows with a missing value are left out."""
        axes = tuple(columns)
        data = np.column_stack([np.asarray(columns[a], float) for a in axes]) if axes else np.zeros((0, 0))
        weight = np.ones(len(data)) if weights is None else np.asarray(weights, float)
        usable = np.isfinite(data).all(axis=1) & np.isfinite(weight)
        step = np.array([float(widths[a]) for a in axes])
        keys = np.floor(data[usable] / step).astype(np.int64)
        return cls(axes, tuple(step.tolist()), *_merge(keys.reshape(-1, len(axes)), weight[usable]))

    @classmethod
    def empty(cls, axes: tuple[str, ...], widths: tuple[float, ...]) -> "SparseHistogram":
        return cls(tuple(axes), tuple(widths), np.zeros((0, len(axes)), np.int64), np.zeros(0))

    def __add__(self, other: "SparseHistogram") -> "SparseHistogram":
        if not isinstance(other, SparseHistogram):
            return NotImplemented
        if (self.axes, self.widths) != (other.axes, other.widths):
            raise UserError(f"cannot add histograms of different bins ({self.axes} {self.widths} and "
                            f"{other.axes} {other.widths}); count both with the same bin widths")
        return SparseHistogram(self.axes, self.widths, *_merge(np.concatenate([self.keys, other.keys]),
                                                               np.concatenate([self.values, other.values])))

    @property
    def total(self) -> float:
        return float(self.values.sum())

    def equals(self, other: "SparseHistogram") -> bool:
        """Same bins and bit-identical values."""
        return ((self.axes, self.widths) == (other.axes, other.widths) and np.array_equal(self.keys, other.keys)
                and np.array_equal(self.values, other.values))

    def frame(self, value_name: str) -> pd.DataFrame:
        """One row per occupied bin: ``<axis>_low``, ``<axis>_high`` per axis and ``value_name``."""
        columns = {}
        for i, (axis, width) in enumerate(zip(self.axes, self.widths)):
            columns[f"{axis}_low"] = self.keys[:, i] * width
            columns[f"{axis}_high"] = (self.keys[:, i] + 1) * width
        columns[value_name] = self.values
        return pd.DataFrame(columns)


def _merge(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sum the values of equal key rows; rows sorted lexicographically."""
    if len(values) == 0:
        return keys.astype(np.int64), values.astype(float)
    unique, where = np.unique(keys, axis=0, return_inverse=True)
    return unique.astype(np.int64), np.bincount(where.ravel(), weights=values, minlength=len(unique))
