"""Equations (1)-(4) on scalars, arrays and Series, against hand-computed values."""

import math

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import road_load
from haulprofile.analysis.vehicle import load_vehicle


@pytest.fixture
def vehicle():
    return load_vehicle("rigid-18t")


def test_hand_computed_point(vehicle):
    # 22 007.4 kg (paper's measured total), 20 m/s, 2 % uphill, 0.3 m/s^2
    m, v, grad, a = 22_007.4, 20.0, 2.0, 0.3
    alpha = math.atan(0.02)
    expected = (m * a + m * 9.81 * vehicle.rolling_resistance_coefficient * math.cos(alpha)
                + m * 9.81 * math.sin(alpha) + 0.5 * 1.2 * vehicle.drag_coefficient * vehicle.frontal_area_m2 * v * v)
    assert road_load.wheel_force_n(v, a, grad, m, vehicle) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("wrap", [np.asarray, pd.Series])
def test_arrays_and_series(vehicle, wrap):
    speed = wrap([0.0, 10.0, 25.0])
    force = road_load.wheel_force_n(speed, wrap([0.0, 0.0, 0.0]), wrap([0.0, 0.0, 0.0]), 20_000.0, vehicle)
    assert np.asarray(force)[0] == pytest.approx(20_000 * 9.81 * vehicle.rolling_resistance_coefficient)


def test_acceleration_inverts_wheel_force(vehicle):
    rng = np.random.default_rng(1)
    v, a, g = rng.uniform(0, 25, 50), rng.normal(0, 1, 50), rng.normal(0, 4, 50)
    force = road_load.wheel_force_n(v, a, g, 18_000, vehicle, rotating_mass_kg=300)
    np.testing.assert_allclose(road_load.acceleration_mps2(force, v, g, 18_000, vehicle, 300), a, atol=1e-9)


def test_wheel_torque_from_engine(vehicle):
    # 1200 rpm in a gear whose total ratio is 10: v = omega_eng / i * r
    ratio, rpm = 10.0, 1200.0
    v = 2 * math.pi * rpm / 60 / ratio * vehicle.wheel_radius_m
    torque = road_load.wheel_torque_from_engine_nm(1000.0, rpm, v, vehicle.wheel_radius_m, 0.93)
    assert torque == pytest.approx(0.93 * ratio * 1000.0)
    assert np.isnan(road_load.wheel_torque_from_engine_nm(1000.0, rpm, 0.0, vehicle.wheel_radius_m, 0.93))
