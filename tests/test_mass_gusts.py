"""The head-wind gusts' share of the joint mass fit's covariance (`mass.gusts`): the exponential
kernel's recursion against the dense sum, and on synthetic drives whose gusts follow the model the
stated sigma against the spread of the masses over drives."""

import numpy as np

from haulprofile.analysis.kinematics import distance_m
from haulprofile.analysis.mass.gusts import _kernel_sums
from haulprofile.analysis.mass.joint import JointSettings, fit_joint, wind_regressors
from haulprofile.analysis.road_load import AIR_DENSITY_KGPM3, G_MPS2
from haulprofile.analysis.vehicle import load_vehicle

VEHICLE = load_vehicle("rigid-18t")
C_R, CDA = 0.0072, 5.6
MASSES = (16_000.0, 11_000.0, 18_500.0)
WIND = (4.0, -2.0)


def _gusty_drive(seed, n_per=3000, intensity=0.37, length_m=150.0):
    """10 Hz samples of three segments on a road that turns (so the mean wind can be fitted), with a
    mean wind and gusts of ``intensity`` times its speed, Gauss-Markov over ``length_m`` of travel;
    returns the `fit_joint` arguments and the wind columns."""
    rng = np.random.default_rng(seed)
    n = n_per * len(MASSES)
    time_s = np.arange(n) * 0.1
    speed = 12 + 6 * np.sin(time_s / 40 + seed) + 2 * np.sin(time_s / 13)
    accel = np.gradient(speed, time_s)
    angle = np.arctan(0.03 * np.sin(time_s / 45 + seed) + 0.01 * np.sin(time_s / 11))
    distance = distance_m(time_s, speed)
    heading = distance / 700.0
    east, north = np.cumsum(speed * np.cos(heading) * 0.1), np.cumsum(speed * np.sin(heading) * 0.1)
    grid = np.arange(0.0, distance[-1] + 2.0, 1.0)
    phi = np.exp(-1.0 / length_m)
    gust = np.empty(len(grid))
    state = rng.standard_normal()
    for k, step in enumerate(rng.standard_normal(len(grid)) * np.sqrt(1 - phi * phi)):
        state = phi * state + step
        gust[k] = state
    head = (-(WIND[0] * np.cos(heading) + WIND[1] * np.sin(heading))
            + intensity * np.hypot(*WIND) * np.interp(distance, grid, gust))
    mass = np.repeat(MASSES, n_per)
    excess = accel + G_MPS2 * np.sin(angle)
    aero = 0.5 * AIR_DENSITY_KGPM3 * speed ** 2
    force = (mass * (excess + G_MPS2 * C_R * np.cos(angle)) + CDA * (aero + AIR_DENSITY_KGPM3 * speed * head)
             + rng.normal(0, 600, n))
    bounds = [(j * n_per, (j + 1) * n_per) for j in range(len(MASSES))]
    usable = excess + G_MPS2 * C_R > 0.05
    drive = (force, excess + rng.normal(0, 0.01, n), np.cos(angle), aero, time_s, bounds, usable)
    return drive, wind_regressors(speed, east, north, time_s)


def test_kernel_sums_equal_the_dense_sum():
    rng = np.random.default_rng(0)
    distance = np.sort(rng.uniform(0, 2000, 300))
    rows = rng.normal(size=(300, 3))
    dense = np.exp(-np.abs(distance[:, None] - distance[None, :]) / 150.0) @ rows
    np.testing.assert_allclose(_kernel_sums(rows, distance, 150.0), dense, rtol=1e-10, atol=1e-10)


def test_the_distance_ignores_a_time_step_back():
    distance = distance_m(np.array([0.0, 1.0, 0.5, 1.5]), np.array([10.0, 10.0, 10.0, 10.0]))
    np.testing.assert_allclose(distance, [0.0, 10.0, 10.0, 20.0])


def test_the_stated_mass_sigma_holds_the_gusts():
    """Over 40 drives whose gusts are as the model says, the stated 1-sigma against the spread of
    the masses: without the gusts' term the blocks stated 0.79 of it."""
    errors, stated, without = [], [], []
    for seed in range(40):
        drive, columns = _gusty_drive(seed)
        fit = fit_joint(*drive, VEHICLE, wind_regressors=columns)
        blocks = fit_joint(*drive, VEHICLE, JointSettings(gust_intensity=0.0), wind_regressors=columns)
        np.testing.assert_array_equal(fit.masses_kg, blocks.masses_kg)  # the term moves sigmas, no mass
        errors.append(fit.masses_kg / np.array(MASSES) - 1)
        stated.append(fit.mass_std_kg / np.array(MASSES))
        without.append(blocks.mass_std_kg / np.array(MASSES))
    errors, stated, without = np.array(errors), np.array(stated), np.array(without)
    spread = np.sqrt(np.mean((errors - errors.mean(axis=0)) ** 2))
    print("stated / spread", np.sqrt(np.mean(stated ** 2)) / spread, "blocks only", np.sqrt(np.mean(without ** 2)) / spread)
    assert 0.9 < np.sqrt(np.mean(stated ** 2)) / spread < 1.2
    assert np.sqrt(np.mean(without ** 2)) / spread < 0.85
    assert np.all(stated >= without)


def test_without_wind_columns_there_is_no_gust_term():
    drive, _ = _gusty_drive(1)
    fit = fit_joint(*drive, VEHICLE)
    blocks = fit_joint(*drive, VEHICLE, JointSettings(gust_intensity=0.0))
    np.testing.assert_array_equal(fit.mass_std_kg, blocks.mass_std_kg)
