"""The smoother's posterior of its gradient errors over the whole grid, for the weighted sums of
them a later stage takes.

The mass fit without an accelerometer uses the estimated gradient as a regressor: its mass moves by
a weighted sum of the gradient's errors over the segment (`mass.gradient_regressor_covariance_kg2`).
Its variance is wᵀ P w with P the gradient's n × n posterior covariance, which the RTS smoother
holds in its gains and smoothed covariances (`kalman.smoother_gains`, `kalman.weighted_sum_covariance`):
the estimator's own correlation of its errors along the road, no length assumed. The gradient's
result carries it (`GradientResult.posteriors`, which the mass stage hands to `estimate_mass`), each
one naming the gradient samples it describes. Not for the gradient `gps+can` fits its mass on
(`force_balance`: GPS altitude's first pass), whose errors hold a bias this posterior does not state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kalman


@dataclass(frozen=True, eq=False)
class GradientPosterior:
    gains: np.ndarray
    """(n, ns, ns) the RTS smoother's gains per grid point (`kalman.smoother_gains`)."""
    gradient_column: np.ndarray
    """(n, ns) the smoothed covariances' gradient column, P_i[:, GAMMA]."""
    lower: np.ndarray
    """Per sample, the grid point at or below its distance (-1: no distance)."""
    fraction: np.ndarray
    """Per sample, its share of the grid point above (the samples are linear between grid points)."""
    gradient_pct: np.ndarray
    """Per sample, the gradient [%] this is the posterior of."""

    def describes(self, gradient_pct) -> bool:
        """Whether ``gradient_pct`` (per sample) is the gradient this is the posterior of."""
        values = np.asarray(gradient_pct, dtype=float)
        return values.shape == self.gradient_pct.shape and np.array_equal(values, self.gradient_pct, equal_nan=True)

    def sum_covariance(self, sample_weights) -> np.ndarray:
        """Covariance (k, k) of the k sums Σ_s W[s, a] e_s over the samples, e_s the error of the
        sample's gradient as tan(α) [-] (a linear mix of its two grid points'); ``sample_weights``
        W (samples, k), 0 where a sample has no distance."""
        weights = np.asarray(sample_weights, dtype=float)
        if weights.ndim == 1:
            weights = weights[:, None]
        n = len(self.gradient_column)
        on_grid = np.zeros((n, weights.shape[1]))
        ok = self.lower >= 0
        np.add.at(on_grid, self.lower[ok], weights[ok] * (1 - self.fraction[ok])[:, None])
        above = ok & (self.fraction > 0)
        np.add.at(on_grid, self.lower[above] + 1, weights[above] * self.fraction[above][:, None])
        return kalman.weighted_sum_covariance(self.gains, self.gradient_column, kalman.GAMMA, on_grid)


def gradient_posterior(gains, gradient_column, distance_m, spacing_m: float, gradient_pct) -> GradientPosterior:
    """The posterior over the grid of spacing ``spacing_m`` [m] with samples at ``distance_m`` [m]
    (NaN: none) linear between the grid points, as `estimate_gradient`'s ``np.interp`` puts them."""
    distance = np.asarray(distance_m, dtype=float)
    n = len(gradient_column)
    position = distance / spacing_m
    inside = np.isfinite(position) & (position >= 0) & (position <= n - 1)
    lower = np.full(len(distance), -1, dtype=np.int64)
    lower[inside] = np.minimum(np.floor(position[inside]).astype(np.int64), n - 1)
    fraction = np.zeros(len(distance))
    fraction[inside] = position[inside] - lower[inside]
    return GradientPosterior(gains=gains, gradient_column=gradient_column, lower=lower, fraction=fraction,
                             gradient_pct=np.asarray(gradient_pct, dtype=float).copy())
