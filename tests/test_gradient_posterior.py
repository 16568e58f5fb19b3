"""The smoother's posterior of its gradient errors along the road (`kalman.weighted_sum_covariance`,
`gradient.posterior`) and the mass's gradient-regressor term built on it
(`mass.gradient_regressor_covariance_kg2`)."""

import numpy as np

from haulprofile.analysis.gradient import kalman
from haulprofile.analysis.gradient.posterior import gradient_posterior
from haulprofile.analysis.mass import gradient_regressor_covariance_kg2, regressor_bias_kg
from haulprofile.analysis.mass.joint import JointSettings, fit_joint
from haulprofile.analysis.road_load import G_MPS2
from haulprofile.analysis.vehicle import load_vehicle

SPACING_M = 10.0
CURVATURE_PSD = 5e-8
GPS_SIGMA_M = 3.0
PRIOR = np.array([100.0, 0.01 ** 2, 1e-6, 1e-8, 1e-8, 1e-6])
PARAMS = np.array([SPACING_M, CURVATURE_PSD, 0.0, 0.0, 1.0, 100.0, G_MPS2, 0.0])


def _gps_road(rng, n_bins):
    """A road drawn from the smoother's own model (height and gradient as an integrated random walk
    of curvature PSD ``CURVATURE_PSD``, the prior ``PRIOR``), GPS altitude on it with white errors
    of ``GPS_SIGMA_M``: (true gradient, measurements, their variances)."""
    q = kalman._process_noise(SPACING_M, 1.0, CURVATURE_PSD, 0.0, 0.0, 1.0, np.exp(-SPACING_M / 100.0))[:2, :2]
    noise = rng.multivariate_normal(np.zeros(2), q, n_bins)
    h, gamma = np.empty(n_bins), np.empty(n_bins)
    h[0], gamma[0] = rng.normal(0, np.sqrt(PRIOR[0])), rng.normal(0, np.sqrt(PRIOR[1]))
    for i in range(1, n_bins):
        h[i] = h[i - 1] + SPACING_M * gamma[i - 1] + noise[i, 0]
        gamma[i] = gamma[i - 1] + noise[i, 1]
    z = np.full((n_bins, kalman.N_MEASUREMENTS), np.nan)
    r = np.full((n_bins, kalman.N_MEASUREMENTS), np.nan)
    z[:, kalman.GPS] = h + rng.normal(0, GPS_SIGMA_M, n_bins)
    r[:, kalman.GPS] = GPS_SIGMA_M ** 2
    return gamma, z, r


def _smooth(z, r):
    """Smoothed states, their covariances and the RTS gains of the GPS-only smoother."""
    n = len(z)
    dt, step = np.ones(n), np.zeros((n, kalman.N_STATES))
    x0, p0 = np.zeros(kalman.N_STATES), np.diag(PRIOR)
    x, p, _, _ = kalman.smooth(z, r, dt, step, PARAMS, x0, p0)
    _, p_filt, _, _ = kalman.smooth(z, r, dt, step, PARAMS, x0, p0, False)
    return x, p, kalman.smoother_gains(p_filt, dt, step, tuple(PARAMS))


def _batch_gradient_covariance(n, r):
    """The gradient's n × n posterior covariance by conditioning the stacked states' joint prior on
    every measurement at once (no smoother involved)."""
    ns = kalman.N_STATES
    f = kalman._transition(SPACING_M, 1.0, np.exp(-SPACING_M / 100.0), ns)
    q = kalman._process_noise(SPACING_M, 1.0, CURVATURE_PSD, 0.0, 0.0, 1.0, np.exp(-SPACING_M / 100.0), ns)
    powers = [np.eye(ns)]
    for _ in range(n):
        powers.append(f @ powers[-1])
    marginal = [np.diag(PRIOR)]
    for _ in range(1, n):
        marginal.append(f @ marginal[-1] @ f.T + q)
    prior = np.zeros((n * ns, n * ns))
    for i in range(n):
        for j in range(i, n):
            block = powers[j - i] @ marginal[i]  # Cov(x_j, x_i) = F^(j-i) P_i
            prior[j * ns:(j + 1) * ns, i * ns:(i + 1) * ns] = block
            prior[i * ns:(i + 1) * ns, j * ns:(j + 1) * ns] = block.T
    rows = np.zeros((n, n * ns))
    rows[np.arange(n), np.arange(n) * ns + kalman.H] = 1.0
    gain = np.linalg.solve(rows @ prior @ rows.T + np.diag(r[:, kalman.GPS]), rows @ prior).T
    posterior = prior - gain @ rows @ prior
    return posterior[kalman.GAMMA::ns, kalman.GAMMA::ns]


def test_the_recursion_equals_the_dense_posterior_of_weighted_sums():
    rng = np.random.default_rng(3)
    _, z, r = _gps_road(rng, 50)
    _, p, gains = _smooth(z, r)
    weights = rng.normal(size=(50, 3))
    weights[:12, 0] = 0.0
    weights[30:, 1] = 0.0
    dense = _batch_gradient_covariance(50, r)
    np.testing.assert_allclose(np.diag(dense), p[:, kalman.GAMMA, kalman.GAMMA], rtol=1e-6)
    got = kalman.weighted_sum_covariance(gains, p[:, :, kalman.GAMMA], kalman.GAMMA, weights)
    np.testing.assert_allclose(got, weights.T @ dense @ weights, rtol=1e-6, atol=1e-12)


def test_the_posterior_holds_the_spread_of_a_segments_summed_gradient_error():
    """Over draws of road and GPS altitude, a long stretch's summed gradient error is as large as
    the posterior says, and far below the errors' σ summed as one error (what the mass took)."""
    rng = np.random.default_rng(5)
    n = 400
    weights = np.zeros(n)
    weights[60:340] = rng.uniform(0.2, 1.0, 280)
    z_scores, full = [], []
    for _ in range(150):
        gamma, z, r = _gps_road(rng, n)
        x, p, gains = _smooth(z, r)
        sigma = np.sqrt(kalman.weighted_sum_covariance(gains, p[:, :, kalman.GAMMA], kalman.GAMMA, weights)[0, 0])
        error = float(weights @ (x[:, kalman.GAMMA] - gamma))
        z_scores.append(error / sigma)
        full.append(float(weights @ np.sqrt(p[:, kalman.GAMMA, kalman.GAMMA])) / sigma)
    z_scores = np.array(z_scores)
    rms = float(np.sqrt(np.mean(z_scores ** 2)))
    print(rms, np.mean(np.abs(z_scores) <= 2), np.median(full))
    assert 0.85 < rms < 1.15
    assert np.mean(np.abs(z_scores) <= 2) >= 0.92
    assert np.median(full) > 4  # the fully correlated statement: several times the spread


VEHICLE = load_vehicle("rigid-18t")
MASSES_KG = (16_000.0, 11_000.0, 18_500.0)


def test_the_mass_sigma_from_the_posterior_holds_the_gradient_regressors_effect_over_draws():
    """A 10 Hz drive of three segments on a road drawn from the smoother's model, its gradient the
    GPS-only smoother's: each segment's mass fitted on that gradient against the same fitted on the
    true one. The term from the posterior, through the whole fit's response (c_r and c_d·A carry a
    segment's regressor error to the others), holds the difference's spread; the gradient's σ taken
    as one error of the segment through its mass alone (main's term) does not."""
    rng = np.random.default_rng(11)
    n_per = 2000
    n = n_per * len(MASSES_KG)
    time_s = np.arange(n) * 0.1
    speed = 15 + 7 * np.sin(time_s / 60) + 3 * np.sin(time_s / 17)
    accel = np.gradient(speed, time_s)
    distance = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * 0.1)])
    n_bins = int(distance[-1] // SPACING_M) + 2
    grid = np.arange(n_bins) * SPACING_M
    mass = np.repeat(MASSES_KG, n_per)
    aero = 0.6 * speed ** 2
    bounds = [(j * n_per, (j + 1) * n_per) for j in range(len(MASSES_KG))]
    z_new, z_old = [], []
    for _ in range(40):
        gamma, z, r = _gps_road(rng, n_bins)
        x, p, gains = _smooth(z, r)
        true_angle = np.arctan(np.interp(distance, grid, gamma))
        estimate = np.interp(distance, grid, x[:, kalman.GAMMA])
        force = mass * (accel + G_MPS2 * np.sin(true_angle) + G_MPS2 * 0.0072 * np.cos(true_angle)) + 5.6 * aero
        force = force + rng.normal(0, 300, n)
        usable = accel + G_MPS2 * np.sin(true_angle) > 0.05
        fits = {}
        for name, angle in (("true", true_angle), ("estimated", np.arctan(estimate))):
            excess = accel + G_MPS2 * np.sin(angle)
            fits[name] = fit_joint(force, excess, np.cos(angle), aero, time_s, bounds, usable, VEHICLE,
                                   JointSettings(), "gradient", regressor_response=True)
        posterior = gradient_posterior(gains, p[:, :, kalman.GAMMA], distance, SPACING_M, 100 * estimate)
        fit = fits["estimated"]
        sigma = np.sqrt(np.diag(gradient_regressor_covariance_kg2(fit, posterior, np.cos(np.arctan(estimate)))))
        stated = G_MPS2 * np.interp(distance, grid, np.sqrt(p[:, kalman.GAMMA, kalman.GAMMA]))
        old = regressor_bias_kg(fit, stated, bounds)
        effect = fit.masses_kg - fits["true"].masses_kg
        both = np.isfinite(effect)  # a segment mostly downhill has too few samples on some roads
        z_new.extend(effect[both] / sigma[both])
        z_old.extend(effect[both] / old[both])
    z_new, z_old = np.array(z_new), np.array(z_old)
    rms_new, rms_old = float(np.sqrt(np.mean(z_new ** 2))), float(np.sqrt(np.mean(z_old ** 2)))
    print(len(z_new), rms_new, np.mean(np.abs(z_new) <= 2), rms_old)
    assert 0.75 < rms_new < 1.25
    assert np.mean(np.abs(z_new) <= 2) >= 0.9
    assert not 0.75 < rms_old < 1.25


def test_the_mass_takes_only_the_posterior_of_the_gradient_it_fits_on():
    import pandas as pd

    from haulprofile.analysis.mass import _gradient_posterior
    rng = np.random.default_rng(2)
    _, z, r = _gps_road(rng, 30)
    x, p, gains = _smooth(z, r)
    distance = np.linspace(0.0, 290.0, 100)
    gradient = 100 * np.interp(distance, np.arange(30) * SPACING_M, x[:, kalman.GAMMA])
    posterior = gradient_posterior(gains, p[:, :, kalman.GAMMA], distance, SPACING_M, gradient)
    frame = pd.DataFrame({"gradient_pct": gradient})
    assert _gradient_posterior(frame, (posterior,)) is posterior
    assert _gradient_posterior(frame.assign(gradient_pct=gradient + 0.1), (posterior,)) is None
    assert _gradient_posterior(frame, ()) is None
    # a sample on a grid point weighs that point alone, one between two splits linearly
    weights = np.zeros((100, 1))
    weights[[0, 50]] = 1.0
    on_grid = np.zeros((30, 1))
    np.add.at(on_grid, [0, 14, 15], [[1.0], [1 - (distance[50] / SPACING_M - 14)], [distance[50] / SPACING_M - 14]])
    np.testing.assert_allclose(posterior.sum_covariance(weights),
                               kalman.weighted_sum_covariance(gains, p[:, :, kalman.GAMMA], kalman.GAMMA, on_grid))
