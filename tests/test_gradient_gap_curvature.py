"""The road's curvature where the force balance stands in for the accelerometer (`gps+can`): the
one whose profile best predicts the force balance where gaps like its own hide it
(`GradientSmoother._curvature_across_force_gaps`), since in its gaps the gradient is the curvature
prior's interpolation. An urban street, smooth over tens of metres (vertical curves) and hilly
over hundreds, braked on in stretches of 100-300 m."""

import numpy as np

from haulprofile.analysis.gradient import kalman
from haulprofile.analysis.gradient.smoother import GradientSmoother, Measurements, SmootherSettings
from haulprofile.analysis.road_load import G_MPS2

SPACING_M = 10.0


def _urban_street(rng, n):
    """Gradient of a street: a random walk of 2e-5 /m smoothed over 60 m (its vertical curves),
    kept within ±9 %; height; GPS altitude's error, correlated over 20 bins."""
    walk = np.cumsum(rng.normal(0, np.sqrt(2e-5 * SPACING_M), n))
    kernel = np.exp(-0.5 * (np.arange(-18, 19) / 6.0) ** 2)
    gamma = np.convolve(walk - np.convolve(walk, np.ones(151) / 151, mode="same"), kernel / kernel.sum(), mode="same")
    gamma = np.clip(gamma, -0.09, 0.09)
    h = np.concatenate([[0.0], np.cumsum(gamma[1:] * SPACING_M)])
    phi = np.exp(-1 / 20)
    gps = np.empty(n)
    gps[0] = rng.normal(0, 4.0)
    for k in range(1, n):
        gps[k] = phi * gps[k - 1] + rng.normal(0, 4.0 * np.sqrt(1 - phi ** 2))
    return gamma, h, gps


def _braking_gaps(rng, n):
    """Stretches of 10-30 bins without a force-balance sample, 15-40 bins apart."""
    gap = np.zeros(n, bool)
    k = int(rng.integers(10, 30))
    while k < n:
        length = int(rng.integers(10, 31))
        gap[k:k + length] = True
        k += length + int(rng.integers(15, 41))
    return gap


def _dem_error(rng, n, sigma_m=3.0, correlation_m=150.0):
    """A DEM's height error, correlated over ``correlation_m``."""
    phi = np.exp(-SPACING_M / correlation_m)
    error = np.empty(n)
    error[0] = rng.normal(0, sigma_m)
    for k in range(1, n):
        error[k] = phi * error[k - 1] + rng.normal(0, sigma_m * np.sqrt(1 - phi ** 2))
    return error


def _drive(seed, n=900):
    rng = np.random.default_rng(seed)
    gamma, h, gps = _urban_street(rng, n)
    gap = _braking_gaps(rng, n)
    z = np.full((n, kalman.N_MEASUREMENTS), np.nan)
    z[:, kalman.DEM] = h + _dem_error(rng, n)
    # the force balance with a mass 10 % light (log of the true over its mass 0.1, its prior 0 ± 0.25):
    # z = e^k (g sin γ + u) - u + b, u = dv/dt + g c_r (stop-and-go: ±0.5 m/s² over 30-bin cycles)
    u = 0.5 * np.sin(np.arange(n) * 2 * np.pi / 30 + rng.uniform(0, 2 * np.pi)) + G_MPS2 * 0.006
    force = np.exp(0.1) * (G_MPS2 * gamma / np.sqrt(1 + gamma ** 2) + u) - u + 0.05
    z[:, kalman.IMU] = np.where(gap, np.nan, force + rng.normal(0, 0.03, n))
    z[:, kalman.GPS] = h + gps
    reset = np.zeros(n)
    reset[0] = 0.25 ** 2
    m = Measurements(z=z, count=np.ones((n, kalman.N_MEASUREMENTS)), h_acc_m=np.full(n, 3.0),
                     v_acc_m=np.full(n, 4.0), dt_s=np.full(n, 1.5), spacing_m=SPACING_M,
                     imu_scale_regressor=np.where(gap, np.nan, u), imu_scale_reset_var=reset)
    return m, gamma, gap


def test_the_curvature_that_predicts_the_force_balance_across_gaps_holds_the_gaps_inside_its_sigma():
    """On streets the likelihood of the innovations takes a stiffer road than the one that
    predicts the force balance across moved gaps (it sees the street's smoothness from bin to
    bin), and its ±2σ misses the true gradient (89-95 % inside on these drives); the predictive
    one holds it on ≥ 95 % of the bins. The gaps' gradient itself is about as good here (within
    11 %: 0.86-1.09 against 0.78-1.01 %-pt); on the matrix's urban drives it is better
    (``docs/estimation.md``)."""
    settings = SmootherSettings(force_balance=True)
    for seed in range(3):
        m, gamma, gap = _drive(seed)
        result = GradientSmoother(m, settings)._estimate()
        assert any("predicts the force balance where gaps like its own" in note for note in result.notes)
        likelihood = GradientSmoother(m, settings)
        likelihood._curvature_across_force_gaps = lambda r: None
        chosen = likelihood._estimate()
        assert result.noise["curvature_psd"] > chosen.noise["curvature_psd"]
        inside = np.abs(result.gradient - gamma) <= 2 * result.gradient_std
        assert inside.mean() >= 0.95
        across = np.sqrt(np.mean((result.gradient[gap] - gamma[gap]) ** 2))
        stiff = np.sqrt(np.mean((chosen.gradient[gap] - gamma[gap]) ** 2))
        assert across < 1.2 * stiff


def test_without_gaps_or_with_a_given_curvature_the_likelihood_or_the_setting_decides():
    m, _, _ = _drive(0)
    z = m.z.copy()
    z[:, kalman.IMU] = np.where(np.isfinite(z[:, kalman.IMU]), z[:, kalman.IMU], 0.05)
    whole = Measurements(z=z, count=m.count, h_acc_m=m.h_acc_m, v_acc_m=m.v_acc_m, dt_s=m.dt_s, spacing_m=SPACING_M)
    smoother = GradientSmoother(whole, SmootherSettings(force_balance=True))
    assert smoother._curvature_across_force_gaps(np.ones((len(z), kalman.N_MEASUREMENTS))) is None
    result = GradientSmoother(m, SmootherSettings(force_balance=True, curvature_psd=1e-6))._estimate()
    assert result.noise["curvature_psd"] == 1e-6
    assert not any("gaps like its own" in note for note in result.notes)
