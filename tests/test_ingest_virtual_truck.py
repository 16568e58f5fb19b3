"""Round trip: virtual truck → MCAP log (the foundation's writer) → ingest.

The ingest must give back what the sensors sent (speed, engine torque, IMU, barometer, humidity,
GPS, weight), bin by bin, within their quantisation, and the truth within quantisation plus the
sensor noise the scenario sets.
"""

import numpy as np
import pytest

from haulprofile.analysis.ingest import ingest_logs
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.analysis.virtual_truck import drive, load_scenario, write_mcap
from haulprofile.analysis.virtual_truck import mcap_log
from haulprofile.analysis.virtual_truck import sensors as sensor_models
from haulprofile.contract import j1939
from haulprofile.analysis.kinematics import distance_m

BIN_NS = 100_000_000


@pytest.fixture(scope="module")
def trip(tmp_path_factory):
    virtual = drive(load_scenario("regional-tunnel"), load_vehicle("rigid-18t"), seed=0)
    path = write_mcap(virtual, tmp_path_factory.mktemp("vt") / "virtual.mcap")
    frame, summary = ingest_logs([path])
    return virtual, frame, summary


def _rows(summary, time_s: np.ndarray) -> np.ndarray:
    """Table row of each sensor sample time [s of the drive]."""
    mono = mcap_log.BOOT_OFFSET_NS + np.round(np.asarray(time_s) * 1e9).astype(np.int64)
    return mono // BIN_NS - summary["t0_mono_ns"] // BIN_NS


def _bin_mean(rows: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    keep = (rows >= 0) & (rows < n)
    total = np.bincount(rows[keep], np.asarray(values, float)[keep], n)
    count = np.bincount(rows[keep], minlength=n)
    with np.errstate(invalid="ignore"):
        return np.where(count > 0, total / count, np.nan)


def _compare(frame, summary, stream, column, table_column, scale=1.0):
    """Largest |table - bin mean of the samples the sensor sent| over bins that have samples."""
    expected = _bin_mean(_rows(summary, stream["time_s"]), stream[column].to_numpy() * scale, len(frame))
    have = np.isfinite(expected)
    assert have.sum() > 0.5 * len(frame) or column in ("fuel_rate_lph", "gross_combination_weight_kg",
                                                       "latitude_deg", "longitude_deg")
    got = frame[table_column].to_numpy()[have]
    assert np.isfinite(got).all(), table_column
    return np.max(np.abs(got - expected[have]))


def test_can_signals_are_what_the_sensors_sent(trip):
    virtual, frame, summary = trip
    s = virtual.sensors
    assert summary["warnings"] == [] and frame["valid"].mean() > 0.99
    assert _compare(frame, summary, s["wheel_speed"], "wheel_speed_kmh", "speed_mps", 1 / 3.6) < 1e-9
    assert _compare(frame, summary, s["engine"], "engine_speed_rpm", "engine_speed_rpm") < 1e-9
    reference = s["engine_reference_torque_nm"]
    assert (frame["engine_reference_torque_nm"].dropna() == reference).all()
    assert _compare(frame, summary, s["engine"], "actual_engine_torque_pct", "engine_torque_nm",
                    reference / 100) < 1e-6
    assert _compare(frame, summary, s["pedals"], "accelerator_pedal_pct", "accelerator_pedal_pct") < 1e-9
    assert _compare(frame, summary, s["fuel"], "fuel_rate_lph", "fuel_rate_lph") < 1e-9
    assert _compare(frame, summary, s["weight"], "gross_combination_weight_kg", "reported_mass_kg") < 1e-9


def test_sensor_values_are_what_the_sensors_sent(trip):
    virtual, frame, summary = trip
    s = virtual.sensors
    assert _compare(frame, summary, s["barometer"], "pressure_pa", "pressure_pa") < 1e-6
    assert _compare(frame, summary, s["humidity"], "relative_humidity_pct", "relative_humidity_pct") < 1e-9
    assert _compare(frame, summary, s["humidity"], "temperature_c", "air_temperature_c") < 1e-9
    for axis in "xyz":
        error = _compare(frame, summary, s["imu"], f"accel_{axis}_raw", f"accel_{axis}_mps2",
                         sensor_models.ACCEL_SCALE_MPS2_PER_LSB)
        assert error < 1e-9, axis
    gps = s["gps"][s["gps"]["fix_quality"] > 0]
    assert _compare(frame, summary, gps, "latitude_deg", "latitude_deg") == 0.0
    assert _compare(frame, summary, gps, "longitude_deg", "longitude_deg") == 0.0


def test_truth_within_quantisation_and_noise(trip):
    virtual, frame, summary = trip
    truth = virtual.truth
    noise = virtual.scenario.sensors
    rows = _rows(summary, truth["time_s"])
    keep = (rows >= 0) & (rows < len(frame))
    speed = frame["speed_mps"].to_numpy()[rows[keep]]
    error = np.abs(speed - truth["speed_mps"].to_numpy()[keep])
    # the wheel speed sensor samples 4 ms into each 100 ms; the truck moves on within it
    bound = (0.5 * j1939.SPNS["wheel_speed_kmh"].resolution + 4 * noise.wheel_speed_noise_kmh) / 3.6 \
        + 0.1 * np.abs(truth["accel_mps2"].to_numpy()[keep])
    assert np.mean(error <= bound + 1e-6) > 0.99
    reference = virtual.sensors["engine_reference_torque_nm"]
    torque = frame["engine_torque_nm"].to_numpy()[rows[keep]]
    torque_error = np.abs(torque - truth["engine_torque_nm"].to_numpy()[keep])
    steady = ~truth["shifting"].to_numpy()[keep]
    torque_bound = (0.5 + 4 * noise.engine_torque_noise_pct / np.sqrt(10)) / 100 * reference
    assert np.median(torque_error[steady]) <= torque_bound
    distance = distance_m(frame["time_s"], frame["speed_mps"])[-1]
    assert distance == pytest.approx(truth["distance_m"].iloc[-1], rel=2e-3)


def test_wall_clock_from_gps_time(trip):
    virtual, frame, summary = trip
    start = virtual.scenario.start_epoch_ns
    expected = start + summary["t0_mono_ns"] - mcap_log.BOOT_OFFSET_NS + np.arange(len(frame)) * BIN_NS
    assert np.max(np.abs(frame["wall_time_ns"].to_numpy() - expected)) < 1000
