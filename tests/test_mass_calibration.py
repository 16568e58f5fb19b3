"""The torque-gain calibration as the linear-Gaussian update it is (`mass.calibration`): a weighing
observes z = m̂_w - m_w = m_w δ + e_w; the other segments take E[m_j δ + e_j | z] off, as much of
the weighed segment's error as they share with it. Posteriors computed by hand, the two limits
(errors shared in full, errors far wider than the gain's prior) and the posterior sigma's coverage
over many draws."""

import numpy as np
import pytest

from haulprofile.analysis.errors import UserError
from haulprofile.analysis.mass.calibration import calibrate

GAIN_SIGMA = 0.036
TRUE_KG = np.array([20_000.0, 30_000.0, 25_000.0])


def test_without_a_weighing_only_the_gain_prior_is_added_whatever_the_covariance():
    masses, statistical, other = TRUE_KG * 1.02, np.array([300.0, 400.0, 500.0]), np.array([100.0, 0.0, 250.0])
    expected = np.sqrt(statistical ** 2 + other ** 2 + (masses * GAIN_SIGMA) ** 2)
    for covariance in (None, np.full((3, 3), 1e6)):
        corrected, sigma, gain = calibrate(masses, statistical, other, {}, GAIN_SIGMA, covariance)
        assert np.array_equal(corrected, masses) and np.array_equal(sigma, expected)
        assert gain == {"gain": 1.0, "relative_std": GAIN_SIGMA, "calibrated_from": None}


def test_two_segments_with_independent_errors_by_hand():
    gain = 1.03
    masses = np.array([20_000.0 * gain + 300.0, 30_000.0 * gain - 200.0])
    statistical = np.array([400.0, 500.0])
    corrected, sigma, posterior = calibrate(masses, statistical, np.zeros(2), {0: 20_000.0}, GAIN_SIGMA)
    # z = m_w δ + e_w: δ's posterior mean and variance; independent errors: m_1 = m̂_1 / (1 + δ̂)
    z = masses[0] - 20_000.0
    prior = GAIN_SIGMA ** 2
    delta = prior * 20_000.0 * z / (prior * 20_000.0 ** 2 + statistical[0] ** 2)
    delta_var = prior * statistical[0] ** 2 / (prior * 20_000.0 ** 2 + statistical[0] ** 2)
    assert corrected[0] == 20_000.0 and sigma[0] == 0.0
    assert corrected[1] == pytest.approx(masses[1] / (1 + delta), rel=1e-12)
    assert sigma[1] == pytest.approx(np.sqrt(statistical[1] ** 2 + (masses[1] / (1 + delta)) ** 2 * delta_var), rel=1e-9)
    assert posterior["gain"] == pytest.approx(1 + delta, rel=1e-12)
    assert posterior["relative_std"] == pytest.approx(np.sqrt(delta_var) / (1 + delta), rel=1e-9)
    assert posterior["calibrated_from"] == [1]
    # the weighed segment's own 300 kg is not all gain: the old ratio (1.045) took it for gain
    assert 1.03 < posterior["gain"] < masses[0] / 20_000.0


def test_several_weighings_by_hand():
    masses = TRUE_KG * 0.97 + np.array([150.0, -250.0, 100.0])
    statistical = np.array([300.0, 600.0, 450.0])
    known = {0: TRUE_KG[0], 1: TRUE_KG[1]}
    corrected, sigma, posterior = calibrate(masses, statistical, np.zeros(3), known, GAIN_SIGMA)
    precision = 1 / GAIN_SIGMA ** 2 + sum(kg ** 2 / statistical[j] ** 2 for j, kg in known.items())
    delta = sum(kg * (masses[j] - kg) / statistical[j] ** 2 for j, kg in known.items()) / precision
    assert posterior["gain"] == pytest.approx(1 + delta, rel=1e-12)
    assert posterior["relative_std"] == pytest.approx(np.sqrt(1 / precision) / (1 + delta), rel=1e-9)
    assert corrected[2] == pytest.approx(masses[2] / (1 + delta), rel=1e-12)
    assert sigma[2] == pytest.approx(np.hypot(statistical[2], masses[2] / (1 + delta) / np.sqrt(precision)), rel=1e-9)
    assert list(corrected[:2]) == list(TRUE_KG[:2]) and list(sigma[:2]) == [0.0, 0.0]
    assert posterior["calibrated_from"] == [1, 2]


def test_a_pure_gain_error_is_taken_out_exactly():
    masses = TRUE_KG * 1.05
    corrected, sigma, posterior = calibrate(masses, np.full(3, 1e-3), np.zeros(3), {1: TRUE_KG[1]}, GAIN_SIGMA)
    assert posterior["gain"] == pytest.approx(1.05, rel=1e-9)
    assert corrected == pytest.approx(TRUE_KG, rel=1e-9)
    assert np.all(sigma < 1e-2)


def test_errors_shared_in_full_are_corrected_in_full():
    """Each segment 4 % high by one error the fit shares among them (a wind, a c_d·A), the torque
    report right: the weighing takes the 4 % off the others too, with a posterior sigma of ~0."""
    masses = TRUE_KG * 1.04
    shared = 0.03 * masses
    covariance = np.outer(shared, shared)
    corrected, sigma, _ = calibrate(masses, shared, np.zeros(3), {0: TRUE_KG[0]}, GAIN_SIGMA, covariance)
    assert np.abs(corrected / TRUE_KG - 1).max() < 1e-3
    assert np.all(sigma[1:] < 1e-3 * TRUE_KG[1:])
    # the same errors taken as independent: the weighed one's 4 % is shared with the gain's prior only
    independent, wide, _ = calibrate(masses, shared, np.zeros(3), {0: TRUE_KG[0]}, GAIN_SIGMA)
    assert np.all(np.abs(independent[1:] / TRUE_KG[1:] - 1) > 0.01) and np.all(wide[1:] > 0.02 * TRUE_KG[1:])


def test_independent_errors_much_wider_than_the_gain_prior_correct_almost_nothing():
    masses = TRUE_KG * np.array([1.10, 1.0, 0.98])
    statistical = 0.20 * masses
    corrected, sigma, posterior = calibrate(masses, statistical, np.zeros(3), {0: TRUE_KG[0]}, GAIN_SIGMA)
    # the weighed segment is 10 % off; of that the others take (0.036² / (0.036² + 0.2²)) ~ 3 %
    assert np.all(np.abs(corrected[1:] / masses[1:] - 1) < 0.005)
    assert posterior["relative_std"] > 0.95 * GAIN_SIGMA
    prior_sigma = np.sqrt(statistical ** 2 + (masses * GAIN_SIGMA) ** 2)
    assert np.all(sigma[1:] < prior_sigma[1:]) and np.all(sigma[1:] > 0.99 * prior_sigma[1:])


def test_segments_without_a_mass_stay_without_one_and_a_weighing_of_one_is_a_user_error():
    masses = np.array([20_600.0, np.nan, 25_750.0])
    covariance = np.diag([300.0, np.nan, 400.0]) ** 2
    corrected, sigma, _ = calibrate(masses, np.array([300.0, np.nan, 400.0]), np.zeros(3), {0: 20_000.0},
                                    GAIN_SIGMA, covariance)
    assert np.isnan(corrected[1]) and np.isnan(sigma[1]) and np.isfinite(corrected[2]) and np.isfinite(sigma[2])
    with pytest.raises(UserError, match="weighed_masses_kg: segment\\(s\\) 2 have no mass"):
        calibrate(masses, np.full(3, 300.0), np.zeros(3), {1: 20_000.0}, GAIN_SIGMA)


@pytest.mark.parametrize("weighed", [(0,), (0, 3)])
def test_the_posterior_sigma_covers_the_truth_over_many_draws(weighed):
    """2000 drives drawn from the model (gain from its prior, errors from a covariance with a shared
    and an independent part): the corrected masses of the unweighed segments lie within their ±2σ
    on 93-97 % of them, and so does the gain."""
    rng = np.random.default_rng(26)
    true = np.array([18_000.0, 26_000.0, 31_000.0, 22_000.0, 14_000.0])
    shared = np.outer(true, np.array([0.012, -0.008]))  # two shared parameters' columns, relative
    covariance = shared @ shared.T + np.diag((0.015 * true) ** 2)
    factor = np.linalg.cholesky(covariance)
    others = [j for j in range(len(true)) if j not in weighed]
    inside, gain_inside = [], []
    for _ in range(2000):
        delta = rng.normal(0.0, GAIN_SIGMA)
        masses = true * (1 + delta) + factor @ rng.standard_normal(len(true))
        corrected, sigma, gain = calibrate(masses, np.sqrt(np.diag(covariance)), np.zeros(len(true)),
                                           {j: true[j] for j in weighed}, GAIN_SIGMA, covariance)
        inside.extend(np.abs(corrected[others] - true[others]) <= 2 * sigma[others])
        gain_inside.append(abs(gain["gain"] - 1 - delta) <= 2 * gain["relative_std"] * gain["gain"])
    assert 0.93 <= np.mean(inside) <= 0.97
    assert 0.93 <= np.mean(gain_inside) <= 0.97


def test_the_joint_fit_states_the_masses_covariance_with_their_shared_part():
    from test_mass_joint import VEHICLE, _drive

    from haulprofile.analysis.mass.joint import fit_joint
    force, excess, cos_angle, aero, time_s, bounds, usable = _drive(gain=1.03, aux_fraction=0.0)
    fit = fit_joint(force, excess, cos_angle, aero, time_s, bounds, usable, VEHICLE)
    covariance = fit.mass_covariance_kg2
    assert covariance.shape == (3, 3) and np.array_equal(np.sqrt(np.diag(covariance)), fit.mass_std_kg)
    assert np.allclose(covariance, covariance.T, rtol=1e-9) and np.linalg.eigvalsh(covariance).min() > 0
    # the shared c_r and c_d·A move every mass together
    correlation = covariance / np.outer(fit.mass_std_kg, fit.mass_std_kg)
    assert np.all(np.abs(correlation[np.triu_indices(3, 1)]) > 0.05)
