"""GPS altitude's correlated error in the σ of the gradient's sums (`kalman.sum_cross_covariance`,
`gradient.gps_correlation`)."""

import numpy as np

from haulprofile.analysis.gradient import kalman
from haulprofile.analysis.gradient.gps_correlation import CorrelatedGpsError
from haulprofile.analysis.gradient.posterior import gradient_posterior

from test_gradient_posterior import CURVATURE_PSD, PRIOR, SPACING_M, _gps_road, _smooth


def test_the_cross_covariance_is_each_gps_heights_influence_on_the_sums():
    """Σ_j Cov(h_i, γ_j) W_j over r_i is how far the smoothed sums move per metre of GPS altitude
    at bin i (the smoother is linear in its measurements): checked by moving each one."""
    rng = np.random.default_rng(3)
    _, z, r = _gps_road(rng, 50)
    x, p, gains = _smooth(z, r)
    weights = rng.normal(size=(50, 2))
    weights[:12, 0] = 0.0
    weights[30:, 1] = 0.0
    got = kalman.sum_cross_covariance(gains, p[:, :, kalman.GAMMA], p[:, kalman.H, :], kalman.GAMMA, kalman.H,
                                      weights) / r[:, [kalman.GPS]]
    moved = np.empty((50, 2))
    for i in range(50):
        shifted = z.copy()
        shifted[i, kalman.GPS] += 1.0
        moved[i] = weights.T @ (_smooth(shifted, r)[0][:, kalman.GAMMA] - x[:, kalman.GAMMA])
    np.testing.assert_allclose(got, moved, atol=1e-12 + 1e-7 * np.abs(moved).max())


def _road(rng, n):
    """Height and gradient drawn from the smoother's own model (as `_gps_road`)."""
    q = kalman._process_noise(SPACING_M, 1.0, CURVATURE_PSD, 0.0, 0.0, 1.0, np.exp(-SPACING_M / 100.0))[:2, :2]
    noise = rng.multivariate_normal(np.zeros(2), q, n)
    height, gamma = np.empty(n), np.empty(n)
    height[0], gamma[0] = rng.normal(0, np.sqrt(PRIOR[0])), rng.normal(0, np.sqrt(PRIOR[1]))
    for i in range(1, n):
        height[i] = height[i - 1] + SPACING_M * gamma[i - 1] + noise[i, 0]
        gamma[i] = gamma[i - 1] + noise[i, 1]
    return height, gamma


def _gauss_markov(rng, n, time_constant_steps):
    phi = np.exp(-1.0 / time_constant_steps)
    out = np.empty(n)
    state = rng.standard_normal()
    for k in range(n):
        state = phi * state + rng.standard_normal() * np.sqrt(1 - phi * phi)
        out[k] = state
    return out


def test_a_correlated_gps_error_is_held_by_the_sums_sigma():
    """Over draws of road and a GPS altitude error of σ 1 m correlated over 40 s (a bin a second),
    taken by the smoother as white of 3 m: a long stretch's summed gradient error has RMS z near 1
    against the posterior with the correlated error, well above it against the posterior alone."""
    rng = np.random.default_rng(7)
    n, tau_s = 400, 40.0
    weights = np.zeros(n)
    weights[60:340] = rng.uniform(0.2, 1.0, 280)
    time_s = np.arange(n, dtype=float)
    with_error, without = [], []
    for _ in range(150):
        height, gamma = _road(rng, n)
        z = np.full((n, kalman.N_MEASUREMENTS), np.nan)
        r = np.full((n, kalman.N_MEASUREMENTS), np.nan)
        z[:, kalman.GPS] = height + _gauss_markov(rng, n, tau_s)
        r[:, kalman.GPS] = 3.0 ** 2
        x, p, gains = _smooth(z, r)
        posterior = gradient_posterior(gains, p[:, :, kalman.GAMMA], np.arange(n) * SPACING_M, SPACING_M,
                                       100 * x[:, kalman.GAMMA], p[:, kalman.H, :],
                                       CorrelatedGpsError(time_s, np.ones(n), tau_s, r[:, kalman.GPS]))
        error = float(weights @ (x[:, kalman.GAMMA] - gamma))
        with_error.append(error / np.sqrt(posterior.sum_covariance(weights)[0, 0]))
        white = kalman.weighted_sum_covariance(gains, p[:, :, kalman.GAMMA], kalman.GAMMA, weights)[0, 0]
        without.append(error / np.sqrt(white))
    rms_with, rms_without = (float(np.sqrt(np.mean(np.square(v)))) for v in (with_error, without))
    print(rms_with, rms_without)
    assert 0.85 < rms_with < 1.15
    assert rms_without > 1.3
