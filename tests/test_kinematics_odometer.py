"""The kinematics stage takes speed, acceleration and distance to the GPS track's scale once, for
every stage after it, and keeps the wheel's own reading (`kinematics.add_kinematics`). Every test
fails on the code before it (no `add_kinematics`, the wheel's speed in every stage)."""

import numpy as np
import pytest
from test_distance_scale import _log

from haulprofile.analysis.gradient.sensor_sets import without_sensors
from haulprofile.analysis.kinematics import KinematicsOptions, add_kinematics, distance_m
from haulprofile.testing.accuracy import sensor_set_signals


def _wheel_log(scale_error):
    """`_log`'s drive as a logger gives it: the wheel's speed, no distance yet."""
    return _log(scale_error).drop(columns=["distance_m"])


def test_a_drive_on_a_long_wheel_reads_the_roads_length_and_speed(tmp_path):
    """The virtual truck on 8 km of long-haul road, its wheel speed +2.09 % (seed 3 of an ±3 %
    scale), through the pipeline's ingest and kinematics: the distance is the road's and the mean
    speed the truth's within 0.2 % (the wheel's: +2.1 %); the wheel's reading is kept, and the
    drive's chapter of the report says what was corrected and by how much."""
    from haulprofile.analysis.pipeline import RunContext, run
    from haulprofile.analysis.report.drive import drive_section
    from haulprofile.analysis.virtual_truck import drive, realism_level, write_mcap
    from haulprofile.testing.accuracy import Case, case_scenario

    virtual = drive(case_scenario(Case("long-haul", "ideal", 3, 8000.0)), seed=3,
                    realism=realism_level("ideal", wheel_scale_pct=3.0))
    injected = virtual.injected["wheel_speed_scale"]
    assert injected == pytest.approx(0.0209, abs=1e-4)
    write_mcap(virtual, tmp_path / "logs" / "drive.mcap")
    ctx = RunContext(inputs=[tmp_path / "logs"], out_dir=tmp_path / "out", vehicle=virtual.vehicle,
                     say=lambda _msg: None)
    run(ctx, until="kinematics")
    signals, summary = ctx.signals, ctx.summary
    assert summary["distance_km"] == pytest.approx(virtual.road.length_m / 1000, rel=0.002)
    assert summary["odometer"]["wheel_distance_km"] == pytest.approx(virtual.road.length_m / 1000 * (1 + injected),
                                                                     rel=0.002)
    assert summary["odometer"]["scale_pct"] == pytest.approx(100 * injected, abs=0.1)
    assert summary["odometer"]["corrected"]
    true_speed = np.interp(signals["time_s"], virtual.truth["time_s"], virtual.truth["speed_mps"])
    moving = true_speed > 1.0
    speed, wheel = signals["speed_mps"].to_numpy(), signals["wheel_speed_mps"].to_numpy()
    assert np.nanmean(speed[moving]) / np.mean(true_speed[moving]) == pytest.approx(1.0, abs=0.002)
    assert np.nanmean(wheel[moving]) / np.mean(true_speed[moving]) == pytest.approx(1 + injected, abs=0.002)
    np.testing.assert_allclose(wheel, speed * (1 + summary["odometer"]["scale_pct"] / 100))
    section = drive_section(signals, summary)
    assert any("reads +2.1" in note and "wheel_speed_mps" in note for note in section.notes)
    assert ("wheel speed against GPS", f"{summary['odometer']['scale_pct']:+.2f} %") in section.kpis


def test_speed_acceleration_and_distance_are_divided_once_by_the_tracks_scale():
    frame = _wheel_log(0.02)
    wheel = frame["speed_mps"].to_numpy().copy()
    result = add_kinematics(frame)
    assert result.corrected and result.wheel_speed_scale == pytest.approx(0.02, abs=1e-3)
    scale = 1 + result.wheel_speed_scale
    np.testing.assert_array_equal(frame["wheel_speed_mps"], wheel)
    np.testing.assert_allclose(frame["speed_mps"], wheel / scale)
    np.testing.assert_allclose(frame["distance_m"], distance_m(frame["time_s"], wheel) / scale)
    assert result.distance_km == pytest.approx(result.wheel_distance_km / scale)
    assert result.summary()["odometer"]["scale_pct"] == pytest.approx(100 * result.wheel_speed_scale)
    accel = frame["accel_mps2"].to_numpy().copy()
    again = add_kinematics(frame)  # a signals table this stage wrote, run again
    assert again.wheel_speed_scale == result.wheel_speed_scale
    np.testing.assert_array_equal(frame["wheel_speed_mps"], wheel)
    np.testing.assert_allclose(frame["speed_mps"], wheel / scale)
    np.testing.assert_allclose(frame["accel_mps2"], accel)


def test_the_correction_switched_off_states_the_scale_and_keeps_the_wheels_speed():
    frame = _wheel_log(0.02)
    wheel = frame["speed_mps"].to_numpy().copy()
    result = add_kinematics(frame, KinematicsOptions(speed_over_track=False))
    assert not result.corrected and result.wheel_speed_scale == pytest.approx(0.02, abs=1e-3)
    assert "wheel_speed_mps" not in frame
    np.testing.assert_array_equal(frame["speed_mps"], wheel)
    assert any("not corrected" in note for note in result.notes)


def test_a_log_without_gps_keeps_the_wheels_speed_and_says_why():
    frame = without_sensors(_wheel_log(0.02), "can-only")
    wheel = frame["speed_mps"].to_numpy().copy()
    result = add_kinematics(frame)
    assert result.wheel_speed_scale is None and not result.corrected
    assert "wheel_speed_mps" not in frame
    np.testing.assert_array_equal(frame["speed_mps"], wheel)
    assert result.distance_km == result.wheel_distance_km
    assert result.notes == ["speed and distance are the wheel's: the log has no GPS track to measure the "
                            "wheel's scale against"]


def test_the_matrixs_sensor_sets_get_what_their_loggers_kinematics_give():
    """The accuracy harness strips sensors from a log whose speed the full set's GPS corrected: a
    logger without GPS has the wheel's speed, distance and acceleration; one with GPS the same
    correction as the full log."""
    full = _wheel_log(0.02)
    wheel = full["speed_mps"].to_numpy().copy()
    add_kinematics(full)
    assert not np.allclose(full["speed_mps"], wheel)
    bare = _wheel_log(0.02).drop(columns=["latitude_deg", "longitude_deg", "gps_h_acc_m"])
    add_kinematics(bare)
    can_only = sensor_set_signals(full, "can-only")
    assert "wheel_speed_mps" not in can_only
    for name in ("speed_mps", "distance_m", "accel_mps2"):
        np.testing.assert_array_equal(can_only[name], bare[name])
    no_imu = sensor_set_signals(full, "no-imu")
    for name in ("speed_mps", "wheel_speed_mps", "distance_m", "accel_mps2"):
        np.testing.assert_array_equal(no_imu[name], full[name])
