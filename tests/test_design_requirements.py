"""Requirements of the design stage on drives with closed forms: constant speed, constant grade."""

import math

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.design import DesignOptions
from haulprofile.analysis.design import requirements as R
from haulprofile.analysis.vehicle import load_vehicle

G = 9.81
RHO = 1.2


@pytest.fixture(scope="module")
def rigid():
    return load_vehicle("rigid-18t")


def steady(speed_mps, gradient_pct, mass_kg, seconds=3600.0):
    time = np.arange(0.0, seconds + 1.0)
    return pd.DataFrame({"time_s": time, "speed_mps": speed_mps, "accel_mps2": 0.0,
                         "gradient_pct": gradient_pct, "mass_kg": mass_kg})


def closed_force(v, grade_pct, m, veh):
    alpha = math.atan(grade_pct / 100.0)
    return (m * G * (veh.rolling_resistance_coefficient * math.cos(alpha) + math.sin(alpha))
            + 0.5 * RHO * veh.drag_coefficient * veh.frontal_area_m2 * v * v)


@pytest.mark.parametrize("grade_pct", [0.0, 4.0, -2.0])
def test_steady_drive_requirements_are_the_road_load(rigid, grade_pct):
    v, m = 22.0, 15_000.0
    force = closed_force(v, grade_pct, m, rigid)
    req = R.wheel_requirements(steady(v, grade_pct, m), rigid, DesignOptions())
    torque = force * rigid.wheel_radius_m
    assert req["peak_wheel_torque_nm"] == pytest.approx(torque, rel=1e-9)
    assert req["peak_wheel_power_w"] == pytest.approx(force * v, rel=1e-9)
    for w in DesignOptions().thermal_windows_s:
        assert req[f"rms_wheel_torque_{w:g}s_nm"] == pytest.approx(abs(torque), rel=1e-9)
        assert req[f"mean_wheel_power_{w:g}s_w"] == pytest.approx(abs(force * v), rel=1e-9)
    expected_kwh_per_km = max(force, 0.0) * 1000.0 / 3.6e6
    assert req["positive_wheel_kwh_per_km"] == pytest.approx(expected_kwh_per_km, rel=1e-6)
    assert req["top_speed_driven_mps"] == v
    assert req["max_gradient_pct"] == pytest.approx(grade_pct)


def test_mass_uncertainty_widens_the_range_by_its_grade_force(rigid):
    v, grade, m, sigma = 15.0, 3.0, 20_000.0, 500.0
    ranges, table = R.requirement_ranges({"hill": steady(v, grade, m, 600.0)}, rigid, DesignOptions(mass_sigmas=2.0),
                                         sigma)
    alpha = math.atan(grade / 100.0)
    per_kg = G * (rigid.rolling_resistance_coefficient * math.cos(alpha) + math.sin(alpha)) * rigid.wheel_radius_m
    span = ranges["peak_wheel_torque_nm"]["high"] - ranges["peak_wheel_torque_nm"]["low"]
    assert span == pytest.approx(4.0 * sigma * per_kg, rel=1e-9)
    assert ranges["peak_wheel_torque_nm"]["value"] == pytest.approx(closed_force(v, grade, m, rigid) * rigid.wheel_radius_m)
    assert set(table["hill"]) == {"low", "estimate", "high"}


def test_moving_rms_of_a_torque_pulse():
    time = np.arange(0.0, 1000.0)
    torque = np.where((time >= 100) & (time < 130), 3000.0, 0.0)
    assert R.moving_rms(torque, time, 30.0) == pytest.approx(3000.0)
    assert R.moving_rms(torque, time, 60.0) == pytest.approx(3000.0 * math.sqrt(0.5))
    assert R.moving_mean(torque, time, 300.0) == pytest.approx(300.0)


def test_acceleration_time_of_a_constant_acceleration():
    time = np.arange(0.0, 60.0, 0.5)
    speed = np.clip(0.5 * (time - 5.0), 0.0, 25.0)
    frame = pd.DataFrame({"time_s": time, "speed_mps": speed})
    # leaves 0.5 m/s at t = 6 s: standstill counts until then; 50 km/h at t = 5 + 13.89/0.5
    assert R.acceleration_time_s(frame, 50 / 3.6) == pytest.approx(5.0 + (50 / 3.6) / 0.5 - 5.5, abs=0.5)
    assert R.acceleration_time_s(frame, 200 / 3.6) is None


def test_static_targets_and_shaft_requirements(rigid):
    options = DesignOptions(design_grade_pct=8.0, startability_grade_pct=15.0)
    gross = rigid.curb_mass_kg + rigid.max_payload_kg
    t = R.static_requirements(rigid, options, 0.0, 5.0, options.design_grade_speed_mps)
    assert t["gross_mass_kg"] == gross
    assert t["startability_force_n"] == pytest.approx(closed_force(0.0, 15.0, gross, rigid)
                                                      + gross * options.start_acceleration_mps2)
    assert t["design_grade_force_n"] == pytest.approx(closed_force(options.design_grade_speed_mps, 8.0, gross, rigid))
    wheel = R.wheel_requirements(steady(20.0, 2.0, 15_000.0, 120.0), rigid, options)
    shaft = R.shaft_requirements(wheel, 10.0, 0.95, rigid.wheel_radius_m)
    assert shaft["peak_machine_torque_nm"] == pytest.approx(wheel["peak_wheel_torque_nm"] / 9.5)
    assert shaft["machine_speed_at_top_speed_rpm"] == pytest.approx(20.0 / rigid.wheel_radius_m * 10 * 60 / (2 * math.pi))
