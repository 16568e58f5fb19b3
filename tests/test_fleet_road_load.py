"""Road load shared by all logs of one truck (`analysis.fleet.road_load`): the per-log moments
reproduce the single-drive joint fit exactly, add across logs, survive pickling; one weighing
calibrates the truck's torque gain for every log; and on a small virtual fleet with a known
torque-report gain error, the masses of the other logs after one weighing and the shared c_r."""

import pickle
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.errors import UserError
from haulprofile.analysis.commands.arguments import parse_fleet_known_masses
from haulprofile.analysis.fleet.road_load import fit_truck, segment_moments
from haulprofile.analysis.mass.joint import fit_joint
from haulprofile.analysis.road_load import G_MPS2
from haulprofile.analysis.vehicle import load_vehicle

VEHICLE = load_vehicle("rigid-18t")
C_R, CDA = 0.0072, 5.6
"""The truth; the vehicle file says 0.0065 and 5.34 m²."""


def synthetic_log(seed, masses, gain=1.0, n_per=4000):
    """10 Hz samples of segments of the given masses: varying speed and gradient, force from the
    road-load equation times the torque gain, with noise. Returns the arrays and the bounds."""
    rng = np.random.default_rng(seed)
    n = n_per * len(masses)
    time_s = np.arange(n) * 0.1
    speed = 15 + 7 * np.sin(time_s / (50 + 7 * seed)) + 3 * np.sin(time_s / 17 + seed)
    accel = np.gradient(speed, time_s)
    angle = np.arctan(0.03 * np.sin(time_s / 45 + seed) + 0.01 * np.sin(time_s / 11))
    mass = np.repeat(masses, n_per)
    excess = accel + G_MPS2 * np.sin(angle)
    aero = 0.6 * speed ** 2
    force = gain * (mass * (excess + G_MPS2 * C_R * np.cos(angle)) + CDA * aero) + rng.normal(0, 400, n)
    bounds = [(j * n_per, (j + 1) * n_per) for j in range(len(masses))]
    usable = excess + G_MPS2 * C_R > 0.05
    # the accelerometer's ψ and, as its instrument, the gradient-based one: independent noise
    return (force, excess + rng.normal(0, 0.01, n), np.cos(angle), aero, time_s, bounds, usable,
            excess + rng.normal(0, 0.01, n))


def log_moments(name, arrays, vehicle=VEHICLE):
    """A log's joint fit and its `SegmentMoments`, through the same function the fleet's map step uses."""
    force, excess, cos_angle, aero, time_s, bounds, usable, instrument = arrays
    fit = fit_joint(force, excess, cos_angle, aero, time_s, bounds, usable, vehicle, regressor_name="imu",
                    instrument=instrument)
    regression = SimpleNamespace(excess_imu=excess, excess_gradient=instrument, cos_angle=cos_angle,
                                 aero_per_cda=aero, force=force)
    segments = [{"start_s": time_s[a], "end_s": time_s[b - 1]} for a, b in bounds]
    return fit, segment_moments(name, SimpleNamespace(joint=fit, regression=regression, segments=segments), time_s)


def test_one_logs_moments_give_its_own_joint_fit():
    fit, moments = log_moments("a", synthetic_log(0, (16_000.0, 11_000.0)))
    truck = fit_truck(moments, VEHICLE)
    masses = np.array([s["mass_kg"] for s in truck["segments"]])
    np.testing.assert_allclose(masses, fit.masses_kg, rtol=2e-4)
    for name in fit.coefficients:
        assert truck[name]["value"] == pytest.approx(fit.coefficients[name], rel=2e-3)
        assert truck[name]["std"] == pytest.approx(fit.coefficient_std[name], rel=0.05)
    # without a weighing, the torque gain's uncertainty is in every mass, as in `analyze mass`
    sigma = np.array([s["mass_uncertainty_kg"] for s in truck["segments"]])
    assert np.all(sigma > 0.03 * masses) and truck["torque_gain"]["calibrated_from"] is None
    assert pickle.loads(pickle.dumps(moments))[0].blocks.tobytes() == moments[0].blocks.tobytes()


MASSES = [(16_000.0, 12_000.0), (18_500.0,), (9_500.0, 14_000.0)]


def synthetic_truck(trial, gain=1.04, vehicle=VEHICLE):
    """Three logs of one truck (segments of ``MASSES``): each log's own fit and all their moments."""
    fits, moments = zip(*(log_moments(f"log-{i}", synthetic_log(10 * trial + i, m, gain=gain, n_per=4000), vehicle)
                          for i, m in enumerate(MASSES)))
    return fits, [part for log in moments for part in log]


def test_logs_of_one_truck_share_c_r_and_one_weighing_calibrates_all_of_them():
    fits, parts = synthetic_truck(0)
    truck = fit_truck(parts, VEHICLE, {("log-0", 1): MASSES[0][0]})
    assert truck["logs"] == 3 and truck["rolling_resistance_coefficient"]["identified"]
    own_std = np.array([fit.coefficient_std["rolling_resistance_coefficient"] for fit in fits])
    shared = truck["rolling_resistance_coefficient"]
    assert shared["std"] < own_std.min()
    assert truck["torque_gain"]["gain"] == pytest.approx(1.04, abs=0.01)
    assert truck["torque_gain"]["calibrated_from"] == [{"log": "log-0", "segment": 1}]
    estimated = np.array([s["mass_kg"] for s in truck["segments"]])
    truth = np.concatenate(MASSES)
    print("mass errors", estimated / truth - 1)
    assert np.all(np.abs(estimated / truth - 1) < 0.01)
    assert truck["segments"][0]["mass_uncertainty_kg"] == 0.0
    with pytest.raises(UserError, match="log-1 segment 2"):
        fit_truck(parts, VEHICLE, {("log-1", 2): 18_000.0})


def test_shared_c_r_is_closer_to_the_truth_than_each_logs_own():
    """Over a few trucks (independent noise), the RMS error of the shared c_r against that of the
    logs' own, with a vehicle file that is right (so only the noise is compared, no datasheet pull)."""
    shared, own = [], []
    exact = replace(VEHICLE, rolling_resistance_coefficient=C_R, drag_coefficient=CDA / VEHICLE.frontal_area_m2)
    for trial in range(1, 5):
        fits, parts = synthetic_truck(trial, gain=1.0, vehicle=exact)
        shared.append(fit_truck(parts, exact)["rolling_resistance_coefficient"]["value"] - C_R)
        own += [fit.coefficients["rolling_resistance_coefficient"] - C_R for fit in fits]
    rms_shared, rms_own = np.sqrt(np.mean(np.square(shared))), np.sqrt(np.mean(np.square(own)))
    print("c_r RMS error shared", rms_shared / C_R, "per log", rms_own / C_R)
    assert rms_shared < 0.6 * rms_own


@pytest.mark.parametrize("item, expected", [("rigid:drive-00.mcap:2=18400", ("rigid", "drive-00.mcap", 2, 18400.0)),
                                            ("rigid:a/b.csv=9000", ("rigid", "a/b.csv", 1, 9000.0))])
def test_fleet_known_mass_arguments(item, expected):
    assert parse_fleet_known_masses([item]) == [expected]


@pytest.mark.parametrize("item", ["18400", "rigid=18400", "rigid:log:0=18400", "rigid:log:x=1", "rigid:log:1=-5",
                                  ":log:1=100"])
def test_bad_fleet_known_mass_is_a_user_error(item):
    with pytest.raises(UserError, match="--known-mass"):
        parse_fleet_known_masses([item])
