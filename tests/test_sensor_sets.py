"""Which sensors a log holds, by name (`gradient.sensor_sets`), and the gradient stage saying it."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.gradient.sensor_sets import SENSOR_SETS, describe, sensor_set, without_sensors
from haulprofile.analysis.gradient.stage import gradient_stage
from haulprofile.analysis.pipeline import RunContext


def full_log(n=600):
    time_s = np.arange(n) * 0.1
    return pd.DataFrame({
        "time_s": time_s, "speed_mps": np.full(n, 15.0), "engine_torque_nm": np.full(n, 900.0),
        "pressure_pa": 101325.0 - 0.12 * 15.0 * time_s * 0.02, "air_temperature_c": 20.0,
        "accel_x_mps2": np.full(n, 0.196), "accel_y_mps2": 0.0, "accel_z_mps2": 9.8,
        "latitude_deg": 47.0 + 1.35e-4 * time_s, "longitude_deg": 11.0, "gps_altitude_m": 500.0 + 0.3 * time_s,
        "gps_h_acc_m": 2.0, "gps_v_acc_m": 3.0,
    })


@pytest.mark.parametrize("name", list(SENSOR_SETS))
def test_a_log_without_a_sets_sensors_is_found_to_be_that_set(name):
    reduced = without_sensors(full_log(), name)
    assert sensor_set(reduced) == name
    assert "speed_mps" in reduced and "engine_torque_nm" in reduced


def test_a_column_without_values_is_no_sensor_and_an_unlisted_set_is_named_by_its_parts():
    log = full_log()
    log["pressure_pa"] = np.nan
    assert sensor_set(log) == "no-baro"
    no_gps = log.drop(columns=["latitude_deg"]).assign(pressure_pa=101000.0)
    assert sensor_set(no_gps) == "baro+imu+can"
    assert describe(no_gps) == "sensor set baro+imu+can: barometer + IMU + CAN (no GPS)"
    with pytest.raises(ValueError, match="unknown sensor set 'gps'"):
        without_sensors(log, "gps")


def test_the_gradient_stage_says_the_sensor_set_and_puts_it_in_the_summary():
    said = []
    ctx = RunContext(inputs=[], out_dir=".", signals=without_sensors(full_log(), "no-imu"), dem_dir=None,
                     say=said.append)
    result = gradient_stage(ctx)
    assert "gradient: sensor set no-imu: barometer + GPS + CAN (no IMU)" in said
    assert result.summary()["sensor_set"] == "no-imu"
