"""The engine's drag on overrun from J1939 SPN 514 and the torque report's offset it reveals
(`gradient.engine_drag`), and their use in the `gps+can` force balance."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.gradient import engine_drag
from haulprofile.analysis.vehicle import load_vehicle


def overrun_log(offset_nm=30.0, applications=12, seed=3):
    """A 10 Hz log of a truck in 7th gear: pulling at 600 Nm, braking in gear ``applications``
    times for 5 s each with the engine motored (the net report = -friction + offset), and one
    brake application in neutral (engine at idle) that must not count."""
    vehicle = load_vehicle("rigid-18t")
    rng = np.random.default_rng(seed)
    n = 200 * applications + 100
    ratio = vehicle.total_ratios[6]
    speed = np.full(n, 8.0)
    rpm = speed / vehicle.wheel_radius_m * ratio * 30 / np.pi
    friction = 0.03 * 2000 + 0.05 * 2000 * np.clip((rpm - 600) / 1400, 0, 1)
    brake = np.zeros(n, bool)
    for k in range(applications):
        brake[200 * k + 100: 200 * k + 150] = True
    neutral = np.zeros(n, bool)
    neutral[-60:-10] = True
    brake |= neutral
    rpm = np.where(neutral, 600.0, rpm)
    torque = np.where(brake, -friction, 600.0) + offset_nm + rng.normal(0, 5.0, n)
    frame = pd.DataFrame({"time_s": np.arange(n) / 10.0, "speed_mps": speed, "engine_speed_rpm": rpm,
                          "brake_switch": brake.astype(float), "engine_torque_nm": np.where(neutral, 0.0, torque),
                          "engine_friction_torque_nm": np.round(friction / 20.0) * 20.0})
    return frame, vehicle, brake & ~neutral


def test_the_overrun_samples_are_the_braking_ones_in_gear_above_idle():
    frame, vehicle, in_gear_braking = overrun_log()
    assert np.array_equal(engine_drag.overrun(frame, vehicle), in_gear_braking)
    assert not engine_drag.overrun(frame.drop(columns=["engine_friction_torque_nm"]), vehicle).any()


@pytest.mark.parametrize("offset_nm", [-40.0, 0.0, 30.0])
def test_the_torque_reports_offset_is_what_it_reads_above_minus_the_friction_on_overrun(offset_nm):
    """In a fuel cut the net report is minus SPN 514; what it reads above that is its offset. The
    sigma holds the friction map's 10 % and the spread between the brake applications."""
    frame, vehicle, _ = overrun_log(offset_nm)
    found = engine_drag.torque_report_offset(frame, vehicle)
    assert found.applications == 12 and found.samples == 12 * 50
    friction = np.median(frame["engine_friction_torque_nm"][engine_drag.overrun(frame, vehicle)])
    assert found.sigma_nm >= engine_drag.FRICTION_MAP_UNCERTAINTY * friction
    # the friction column is quantised to 20 Nm here; the offset is found to within that
    assert abs(found.offset_nm - offset_nm) <= 2 * found.sigma_nm
    assert abs(found.offset_nm - offset_nm) < 15.0


def test_no_offset_without_spn_514_or_with_too_few_brake_applications():
    frame, vehicle, _ = overrun_log()
    assert engine_drag.torque_report_offset(frame.drop(columns=["engine_friction_torque_nm"]), vehicle) is None
    few, vehicle, _ = overrun_log(applications=2)
    assert engine_drag.torque_report_offset(few, vehicle) is None


def test_the_engines_drag_at_the_wheels_is_minus_the_friction_through_the_gear():
    frame, vehicle, in_gear_braking = overrun_log()
    force = engine_drag.overrun_wheel_force_n(frame, vehicle)
    assert np.array_equal(np.isfinite(force), in_gear_braking)
    expected = -frame["engine_friction_torque_nm"] * vehicle.total_ratios[6] * vehicle.driveline_efficiency \
        / vehicle.wheel_radius_m
    assert np.allclose(force[in_gear_braking], expected[in_gear_braking], rtol=1e-6)



def test_the_accessories_on_overrun_are_drag_the_wheels_pay_and_not_part_of_the_reports_offset():
    """In a fuel cut the wheels drive the compressor and fan through the crankshaft with the
    friction: the net report stays at -friction + offset (SPN 513 holds no accessories), SPN 2978
    says what they take. The offset is found as without them; the drag at the wheels holds both."""
    frame, vehicle, in_gear_braking = overrun_log(offset_nm=30.0)
    on = np.zeros(len(frame), bool)
    on[::400] = True
    compressor = np.where(np.convolve(on, np.ones(260), "same") > 0, 45.0, 0.0)
    frame["engine_parasitic_torque_nm"] = compressor
    assert (compressor[in_gear_braking] > 0).any() and (compressor[in_gear_braking] == 0).any()
    found = engine_drag.torque_report_offset(frame, vehicle)
    assert abs(found.offset_nm - 30.0) < 15.0
    force = engine_drag.overrun_wheel_force_n(frame, vehicle)
    expected = -(frame["engine_friction_torque_nm"] + compressor) * vehicle.total_ratios[6] \
        * vehicle.driveline_efficiency / vehicle.wheel_radius_m
    assert np.allclose(force[in_gear_braking], expected[in_gear_braking], rtol=1e-6)
