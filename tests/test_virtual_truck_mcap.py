"""The virtual truck's MCAP log follows the data contract and decodes back to its truth."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from haulprofile import contract
from haulprofile.contract import j1939
from haulprofile.analysis.virtual_truck import drive, load_scenario, write_mcap
from haulprofile.analysis.virtual_truck.mcap_log import BOOT_OFFSET_NS

SHORT = """
[scenario]
name = "short-log"
vehicle = "rigid-18t"
start_latitude_deg = 47.5
start_longitude_deg = 8.5
start_time = 2025-05-14T06:30:00Z

[route]
initial_stop_s = 5.0
final_stop_s = 5.0

[[route.section]]
length_m = 2500
speed_kmh = 60

[[tunnel]]
start_m = 1000.0
length_m = 800.0

[payload]
initial_kg = 4000.0
"""


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    path = tmp_path_factory.mktemp("scenario") / "short.toml"
    path.write_text(SHORT)
    return load_scenario(path)


@pytest.fixture(scope="module")
def virtual(scenario):
    return drive(scenario, seed=1)


@pytest.fixture(scope="module")
def log(virtual, tmp_path_factory):
    path = write_mcap(virtual, tmp_path_factory.mktemp("log") / "short.mcap")
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        messages = [(channel.topic, message, channel) for _, channel, message in reader.iter_messages()]
    return path, summary, messages


def _topic(messages, name):
    return [(m, c) for t, m, c in messages if t == name]


def _frames(messages):
    return np.concatenate([contract.unpack(contract.CAN_FRAMES, m.data) for m, _ in _topic(messages, "/can/frames")])


def _decoded(frames, pgn):
    chosen = [f for f in frames if j1939.parse_id(int(f["arbitration_id"]))[1] == pgn]
    return chosen, [j1939.decode_pgn(pgn, bytes(f["data"][:f["dlc"]])) for f in chosen]


def test_topics_schemas_and_times(log, virtual, scenario):
    _, summary, messages = log
    topics = {c.topic for c in summary.channels.values()}
    assert topics == {"/can/frames", "/imu", "/imu/temperature", "/barometer", "/humidity", "/gps/fix", "/time/sync"}
    for channel in summary.channels.values():
        topic = contract.TOPICS[channel.topic]
        assert channel.message_encoding == topic.encoding
        assert summary.schemas[channel.schema_id].name == topic.schema_name
    for _, message, _ in messages:
        assert message.log_time - scenario.start_epoch_ns == message.publish_time - BOOT_OFFSET_NS
    assert messages[-1][1].publish_time - BOOT_OFFSET_NS <= virtual.duration_s * 1e9 + 2e8


def test_can_batches_are_bounded(log):
    _, _, messages = log
    for message, _ in _topic(messages, "/can/frames"):
        batch = contract.unpack(contract.CAN_FRAMES, message.data)
        assert len(batch) <= 512
        assert batch["t_mono_ns"][-1] - batch["t_mono_ns"][0] <= 200_000_000
        assert np.all(batch["flags"] & contract.CAN_FLAG_EXTENDED)


def test_eec1_and_ccvs1_decode_to_the_truth_within_resolution(log, virtual):
    frames = _frames(log[2])
    states = virtual.states
    chosen, values = _decoded(frames, j1939.PGN_EEC1)
    t = (np.array([f["t_mono_ns"] for f in chosen]) - BOOT_OFFSET_NS) / 1e9
    rpm = np.array([v["engine_speed_rpm"] for v in values])
    assert np.array_equal(rpm, virtual.sensors["engine"]["engine_speed_rpm"].to_numpy())
    truth_rpm = np.interp(t, states["time_s"], states["engine_speed_rpm"])
    assert np.max(np.abs(rpm - truth_rpm)) <= 0.0625 + 5 * 2.0
    torque = np.array([v["actual_engine_torque_pct"] for v in values]) / 100 * 2300.0
    held = states["engine_torque_nm"].to_numpy()[np.searchsorted(states["time_s"], t, side="right") - 1]
    assert np.max(np.abs(torque - held)) <= (0.5 + 5 * 0.3) / 100 * 2300.0

    chosen, values = _decoded(frames, j1939.PGN_CCVS1)
    t = (np.array([f["t_mono_ns"] for f in chosen]) - BOOT_OFFSET_NS) / 1e9
    kmh = np.array([v["wheel_speed_kmh"] for v in values])
    assert np.max(np.abs(kmh - np.interp(t, states["time_s"], states["speed_mps"]) * 3.6)) <= 1 / 512 + 5 * 0.05
    brake = np.array([v["brake_switch"] for v in values])
    assert brake.max() == 1 and brake.min() == 0


def test_ec1_reference_torque_arrives_by_bam(log, virtual):
    frames = _frames(log[2])
    pgns = [j1939.parse_id(int(f["arbitration_id"]))[1] for f in frames]
    cm = next(i for i, p in enumerate(pgns) if p == j1939.PGN_TP_CM)
    data = bytes(frames[cm]["data"])
    assert data[0] == j1939.TP_CM_BAM and int.from_bytes(data[5:8], "little") == j1939.PGN_EC1
    size, packets = data[1] | data[2] << 8, data[3]
    dts = [bytes(frames[i]["data"]) for i, p in enumerate(pgns) if p == j1939.PGN_TP_DT and i > cm][:packets]
    assert [d[0] for d in dts] == list(range(1, packets + 1))
    payload = b"".join(d[1:] for d in dts)[:size]
    assert j1939.decode_pgn(j1939.PGN_EC1, payload)["engine_reference_torque_nm"] == 2300.0
    assert virtual.sensors["engine_reference_torque_nm"] == 2300.0


def test_imu_counts_and_scales(log, virtual):
    _, _, messages = log
    imu = _topic(messages, "/imu")
    metadata = imu[0][1].metadata
    samples = np.concatenate([contract.unpack(contract.IMU, m.data) for m, _ in imu])
    accel = samples["accel_raw"] * float(metadata["accel_scale_mps2_per_lsb"])
    assert np.array_equal(accel[:, 0], virtual.sensors["imu"]["accel_x_mps2"].to_numpy())
    assert float(metadata["accel_scale_mps2_per_lsb"]) == pytest.approx(0.122e-3 * 9.80665)
    assert float(metadata["gyro_scale_radps_per_lsb"]) == pytest.approx(8.75e-3 * np.pi / 180)
    # eq. (7): at rest the accelerometer reads g sin(alpha) plus its bias
    states, sensors = virtual.states, virtual.sensors["imu"]
    expected = np.interp(sensors["time_s"], states["time_s"],
                         states["accel_mps2"] + 9.81 * np.sin(np.arctan(states["gradient_pct"] / 100)))
    residual = sensors["accel_x_mps2"] - expected
    assert abs(np.median(residual)) < 0.2 and np.std(residual) < 0.1


def test_imu_temperature_once_a_second_in_out_temp_steps(log, virtual):
    """The die's temperature as the LSM9DS1's OUT_TEMP gives it (1/16 K, 0 at 25 degC), once a second."""
    _, _, messages = log
    records = np.concatenate([contract.unpack(contract.IMU_TEMPERATURE, m.data)
                              for m, _ in _topic(messages, "/imu/temperature")])
    seconds = (records["t_mono_ns"].astype(np.int64) - BOOT_OFFSET_NS) / 1e9
    assert len(records) == pytest.approx(virtual.duration_s, abs=2)
    assert np.allclose(np.diff(seconds), 1.0, atol=0.01)
    assert np.array_equal(records["temperature_c"], 25.0 + records["temperature_raw"] / 16.0)
    truth = np.interp(seconds, virtual.sensors["imu"]["time_s"], virtual.sensors["imu"]["imu_temperature_c"])
    assert np.all(np.abs(records["temperature_c"] - truth) <= 1 / 32 + 1e-9)


def test_the_imu_temperature_in_a_viewer_copy(log, tmp_path):
    """The Foxglove copy holds every temperature record, as JSON its schema validates."""
    import jsonschema
    from haulprofile.analysis.export import export_logs

    path, _, messages = log
    packed = np.concatenate([contract.unpack(contract.IMU_TEMPERATURE, m.data)
                             for m, _ in _topic(messages, "/imu/temperature")])
    exported = export_logs([path], "foxglove", tmp_path)[0]
    with open(exported.target, "rb") as stream:
        copied = [(schema, json.loads(message.data)) for schema, channel, message in make_reader(stream).iter_messages()
                  if channel.topic == "/imu/temperature"]
    assert [r["temperature_raw"] for _, r in copied] == packed["temperature_raw"].tolist()
    validator = jsonschema.Draft202012Validator(json.loads(copied[0][0].data))
    for _, record in copied:
        validator.validate(record)


def test_a_warming_imu_reaches_the_signals_table(scenario, tmp_path):
    """At `typical` the cab warms the IMU up; the ingest gives its temperature per row, and a logger
    without the IMU (`no-imu`) has none."""
    from haulprofile.analysis.gradient.sensor_sets import without_sensors
    from haulprofile.analysis.ingest import ingest_logs

    warming = drive(scenario, seed=1, realism="typical")
    frame, _ = ingest_logs([write_mcap(warming, tmp_path / "warming.mcap")])
    imu = warming.sensors["imu"]
    truth = np.interp(frame["time_s"], imu["time_s"] - imu["time_s"].iloc[0], imu["imu_temperature_c"])
    logged = frame["imu_temperature_c"].to_numpy()
    assert np.isfinite(logged).mean() > 0.99
    rise_per_s = np.max(np.abs(np.diff(imu["imu_temperature_c"]) / np.diff(imu["time_s"])))
    assert np.nanmax(np.abs(logged - truth)) <= 1 / 32 + 1.5 * rise_per_s + 1e-9  # a count's half, a held second
    assert np.ptp(imu["imu_temperature_c"]) > 0.5  # it did warm up
    assert "imu_temperature_c" not in without_sensors(frame, "no-imu")


def test_barometer_values_come_from_raw_counts_and_follow_the_road(log, virtual):
    _, _, messages = log
    records = np.concatenate([contract.unpack(contract.BAROMETER, m.data) for m, _ in _topic(messages, "/barometer")])
    raw = records["pressure_raw"]
    pressure = records["pressure_pa"]
    assert np.array_equal(pressure, raw * 100 / 4096)
    temp = records["temperature_c"]
    assert np.array_equal(temp, 42.5 + records["temperature_raw"] / 480)
    height = 44330.8 * (1 - (pressure / 101325.0) ** (1 / 5.255))   # eq. (6)
    truth = np.interp(virtual.sensors["barometer"]["time_s"], virtual.states["time_s"], virtual.states["road_height_m"])
    change = (height - height[0]) - (truth - truth[0])
    assert np.max(np.abs(change)) < 5.0     # weather drift over a few minutes plus noise


def test_gps_fixes_are_location_fixes_and_vanish_in_the_tunnel(log, virtual):
    _, _, messages = log
    fixes = [json.loads(m.data) for m, _ in _topic(messages, "/gps/fix")]
    gps = virtual.sensors["gps"]
    assert len(fixes) == int((gps["fix_quality"] > 0).sum()) < len(gps)
    for key in ("timestamp", "frame_id", "latitude", "longitude", "altitude", "position_covariance",
                "position_covariance_type"):
        assert key in fixes[0]
    assert fixes[0]["position_covariance"][0] == pytest.approx(fixes[0]["h_acc_m"] ** 2)
    syncs = [json.loads(m.data) for m, _ in _topic(messages, "/time/sync")]
    assert len(syncs) == pytest.approx(virtual.duration_s, abs=2)
    assert any(s["gps_time_utc_ns"] is None for s in syncs)


def test_same_seed_same_bytes_other_seed_other_bytes(log, scenario, tmp_path):
    path = log[0]
    again = write_mcap(drive(scenario, seed=1), tmp_path / "again.mcap")
    other = write_mcap(drive(scenario, seed=2), tmp_path / "other.mcap")
    assert again.read_bytes() == path.read_bytes()
    assert other.read_bytes() != path.read_bytes()
