"""GPS altitude's correlated error in the σ of the gradient's long sums.

The smoother takes GPS altitude as white noise of an inflated variance (`SmootherSettings.
gps_sigma_factor`); a receiver's altitude error is correlated over seconds to minutes (the
atmosphere, the orbits, multipath). White noise of that size averages out over a mass segment's
heights, the correlated error does not: the smoother's posterior wᵀ P w of a segment's summed
gradient error states too little (`posterior.GradientPosterior`).

The smoothed estimate is linear in the measurements: x̂ = P Hᵀ R⁻¹ z + (the prior's part), P the
stacked states' posterior. A weighted sum S of the smoothed gradient's errors moves with GPS
altitude's bin i by g_i = Cov(h_i, S) / r_i (`kalman.sum_cross_covariance`), r_i the variance the
smoother gave it. Under GPS errors of covariance K instead of diag(r), Var(S) is the posterior's
wᵀ P w less gᵀ diag(r) g plus gᵀ K g: the same estimate, its σ with the error the receiver has.

K is an exponential (first-order Gauss-Markov) correlation in clock time, σ_i σ_j exp(-|t_i - t_j|/τ),
σ_i the receiver's stated accuracy times a scale, both scale and τ from the drive's own GPS
residuals against the smoothed height (`estimate_gps_error`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class CorrelatedGpsError:
    time_s: np.ndarray
    """(n,) clock time [s] of each grid point, standstills included."""
    sigma_m: np.ndarray
    """(n,) σ [m] of GPS altitude's error in each grid point's mean (0: no GPS altitude there)."""
    time_constant_s: float
    """τ [s] of the error's exponential correlation in time."""
    model_variance_m2: np.ndarray
    """(n,) the variance the smoother gave each grid point's GPS altitude (0: none used)."""

    def extra_covariance(self, influence) -> np.ndarray:
        """gᵀ K g − gᵀ diag(r) g (k, k) for the sums' influences ``influence`` g (n, k) [1/m]: how
        much the sums' covariance grows when GPS altitude's error is this one, not the smoother's
        white one. The exponential kernel by one forward recursion over the grid points in time."""
        g = np.asarray(influence, dtype=float)
        used = np.flatnonzero(self.sigma_m > 0)
        scaled = g[used] * self.sigma_m[used, None]
        decay = np.exp(-np.diff(self.time_s[used], prepend=self.time_s[used[0]] if len(used) else 0.0)
                       / self.time_constant_s)
        running = np.zeros(g.shape[1])
        lower = np.zeros((g.shape[1], g.shape[1]))
        for y, factor in zip(scaled, decay):
            running = y + factor * running
            lower += np.outer(y, running)
        full = lower + lower.T - scaled.T @ scaled
        return full - (g * self.model_variance_m2[:, None]).T @ g


MAX_LAG_S = 600.0
"""Longest lag [s] of the residuals' autocorrelation looked at."""
LAG_STEP_S = 2.0


def residual_autocorrelation(values, time_s, max_lag_s: float = MAX_LAG_S, step_s: float = LAG_STEP_S):
    """(lag centres [s], autocorrelation) of a gappy series ``values`` at grid points of clock time
    ``time_s`` (non-decreasing), the pairs' products averaged per ``step_s`` of lag."""
    ok = np.isfinite(values) & np.isfinite(time_s)
    v, t = values[ok] - np.mean(values[ok]), time_s[ok]
    edges = np.arange(0.0, max_lag_s + step_s, step_s)
    total, count = np.zeros(len(edges) - 1), np.zeros(len(edges) - 1)
    for k in range(1, len(v)):
        lag = t[k:] - t[:-k]
        if lag.size == 0 or lag.min() > max_lag_s:
            break
        index = np.floor(lag / step_s).astype(np.int64)
        inside = index < len(total)
        np.add.at(total, index[inside], (v[k:] * v[:-k])[inside])
        np.add.at(count, index[inside], 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        acf = total / count / np.mean(v * v)
    return (edges[:-1] + edges[1:]) / 2, acf


def correlation_time_s(lag_s, acf) -> float:
    """First lag [s] where ``acf`` falls below 1/e, linear between lags; NaN if it never does."""
    ok = np.isfinite(acf)
    lag, acf = lag_s[ok], acf[ok]
    below = np.flatnonzero(acf < np.exp(-1))
    if len(below) == 0:
        return np.nan
    k = below[0]
    if k == 0:
        return float(lag[0])
    return float(lag[k - 1] + (acf[k - 1] - np.exp(-1)) / (acf[k - 1] - acf[k]) * (lag[k] - lag[k - 1]))


def estimate_gps_error(residual_m, height_var_m2, v_acc_m, time_s, model_variance_m2) -> CorrelatedGpsError | None:
    """GPS altitude's correlated error from the drive's own residuals ``residual_m`` (GPS altitude
    minus the smoothed height per grid point, NaN: none) with the smoothed height's variance
    ``height_var_m2``: σ_i = scale × the stated accuracy ``v_acc_m``, scale² the mean of
    (ε² + P_hh) / v_acc² (what the residual misses of the error, as in expectation-maximisation),
    τ where the residuals' autocorrelation in time falls below 1/e. None without enough residuals."""
    residual = np.asarray(residual_m, dtype=float)
    stated = np.fmax(np.asarray(v_acc_m, dtype=float), 1.0)
    ok = np.isfinite(residual) & np.isfinite(stated) & (np.asarray(model_variance_m2) > 0)
    if ok.sum() < 50:
        return None
    scale2 = float(np.mean((residual[ok] ** 2 + height_var_m2[ok]) / stated[ok] ** 2))
    lag, acf = residual_autocorrelation(np.where(ok, residual / stated, np.nan), time_s)
    tau = correlation_time_s(lag, acf)
    if not np.isfinite(tau):
        tau = MAX_LAG_S
    sigma = np.where(ok, np.sqrt(scale2) * stated, 0.0)
    return CorrelatedGpsError(time_s=np.asarray(time_s, dtype=float), sigma_m=sigma, time_constant_s=max(tau, 1e-3),
                              model_variance_m2=np.where(ok, model_variance_m2, 0.0))
