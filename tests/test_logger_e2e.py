"""Done-when test of issue 3: a 10-minute virtual-truck drive through the emulators and the real
daemon (asyncio tasks, queue, writer), read back by the analysis side: every CAN frame the ECU
sent and every sensor sample the emulated sensors delivered is in the log, bit for bit.

The drive runs time-compressed (10 emulated seconds per real second). Sensors without a FIFO are
set to their slower legal rates so that polling keeps up at 10x on a loaded CI machine (at 20x a
scheduling gap of about 100 ms, common while the other test worker compiles numba kernels,
overflowed the LSM9DS1 FIFO); the full-rate path (952 Hz IMU, 25 Hz barometer, 12.5 Hz humidity)
is covered in real time by ``test_logger_daemon.py`` and the benchmark.
"""

from __future__ import annotations

import numpy as np
import pynmea2
import pytest

from haulprofile import contract
from haulprofile.contract import j1939
from haulprofile.logger.config import Config
from haulprofile.logger.emulators.rig import record_drive
from haulprofile.logger.emulators.signals import from_streams

DRIVE_S = 600.0
TIME_SCALE = 10.0


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    virtual_truck = pytest.importorskip("haulprofile.analysis.virtual_truck")
    scenario = virtual_truck.load_scenario("regional-tunnel")
    drive = virtual_truck.drive(scenario, virtual_truck.scenario_vehicle(scenario), seed=3)
    columns = from_streams(drive.sensors)
    keep = columns["time_s"] <= DRIVE_S + 1.0
    columns = {k: v[keep] for k, v in columns.items()}
    config = Config()
    config.i2c.lsm9ds1.odr_hz = 14.9
    config.i2c.lsm9ds1.mag_odr_hz = 1.25
    config.i2c.hts221.odr_hz = 1.0
    config.can.j1939.request_interval_s = 30.0
    out = tmp_path_factory.mktemp("e2e")
    path, daemon, devices = record_drive(columns, out, duration_s=DRIVE_S, time_scale=TIME_SCALE, config=config,
                                         return_rig=True)
    ingest = pytest.importorskip("haulprofile.analysis.ingest.logs")
    return ingest.read_frames([path]), daemon, devices, columns


def test_one_file_no_drops(logged):
    arrays, daemon, devices, _ = logged
    assert len(daemon.storage.files_written) == 1
    for source in daemon.sources:
        overruns = sum(v.get("overruns", 0) for v in source.stats.extra.values() if isinstance(v, dict))
        # a FIFO overrun needs a scheduling gap of 128 ms (LPS25HB at 10x) on this shared machine,
        # as on the real sensor; it is counted. The queue to the writer never drops.
        assert source.stats.drops == overruns, source.name
        print(f"{source.name}: {overruns} FIFO overruns")


def test_every_can_frame_bit_exact(logged):
    arrays, daemon, devices, _ = logged
    received = arrays.can[(arrays.can["flags"] & contract.CAN_FLAG_TX) == 0]
    sent = devices.ecu.sent
    assert len(sent) > 600 * 100
    assert len(received) == len(sent)
    ids = np.array([s[0] for s in sent], dtype=np.uint32)
    extended = np.array([s[1] for s in sent])
    data = np.zeros((len(sent), 8), dtype=np.uint8)
    for i, (_, _, payload) in enumerate(sent):
        data[i, :len(payload)] = np.frombuffer(payload, dtype=np.uint8)
    assert np.array_equal(received["arbitration_id"], ids)
    assert np.array_equal((received["flags"] & contract.CAN_FLAG_EXTENDED) != 0, extended)
    assert np.array_equal(received["data"], data)
    transmitted = arrays.can[(arrays.can["flags"] & contract.CAN_FLAG_TX) != 0]
    can_source = next(s for s in daemon.sources if s.name == "can")
    assert len(transmitted) == can_source.guard.sent
    assert set(transmitted["arbitration_id"].tolist()) <= can_source.guard.allowed


def test_the_engine_reports_its_friction_and_its_accessories_torque(logged):
    """EEC3 (PGN 65247) as the virtual truck's engine sends it, through the emulated ECU: what
    `analyze demo` logs, so the mass there can take the accessories' torque off (SPN 2978)."""
    arrays, _, _, columns = logged
    received = arrays.can[(arrays.can["flags"] & contract.CAN_FLAG_TX) == 0]
    eec3 = received[((received["arbitration_id"] >> 8) & 0x3FFFF) == j1939.PGN_EEC3]
    assert len(eec3) >= 0.9 * DRIVE_S / 0.25
    decoded = [j1939.decode_pgn(j1939.PGN_EEC3, bytes(d)) for d in eec3["data"]]
    for name in ("nominal_friction_torque_pct", "parasitic_loss_torque_pct"):
        sent = {d[name] for d in decoded}
        assert None not in sent and sent <= set(columns[name].tolist()), name
    assert len({d["nominal_friction_torque_pct"] for d in decoded}) > 1  # it follows the engine speed


def test_every_imu_sample_bit_exact(logged):
    arrays, _, devices, _ = logged
    imu = devices.board.models["lsm9ds1"]
    served = np.frombuffer(b"".join(imu.served), dtype="<i2").reshape(-1, 6)
    # Its FIFO holds 215 ms at 10x: a longer scheduling gap of a loaded machine overruns it, as it
    # would the chip's; the loss is counted (`test_one_file_no_drops`), what was read is logged.
    print(f"lsm9ds1: {imu.overwritten} of {imu.produced} samples overwritten before a read")
    assert imu.produced >= DRIVE_S * 14.9 * 0.98
    assert imu.overwritten <= 0.02 * imu.produced
    assert len(served) >= imu.produced - 32 - imu.overwritten
    assert np.array_equal(arrays.imu["gyro_raw"], served[:, :3])
    assert np.array_equal(arrays.imu["accel_raw"], served[:, 3:])


@pytest.mark.parametrize("topic, model, fields", [
    ("/barometer", "lps25hb", ("pressure_raw", "temperature_raw")),
    ("/humidity", "hts221", ("humidity_raw", "temperature_raw")),
    ("/magnetometer", "lsm9ds1_mag", ("magnetic_raw",)),
])
def test_every_sensor_sample_bit_exact(logged, topic, model, fields):
    arrays, _, devices, _ = logged
    emulated = devices.board.models[model]
    # At 10x a sensor without a FIFO (HTS221, magnetometer) loses a sample to any 100 ms scheduling
    # gap of this shared machine (the real sensor too would); what was read is logged bit for bit.
    print(f"{model}: {emulated.overwritten} of {emulated.produced} samples overwritten before a read")
    assert emulated.overwritten <= 0.02 * emulated.produced
    records = arrays.sensors[topic]
    if fields == ("magnetic_raw",):
        logged_raw = [tuple(r) for r in records["magnetic_raw"].tolist()]
    else:
        logged_raw = list(zip(*(records[f].tolist() for f in fields)))
    assert logged_raw == [tuple(s) for s in emulated.served]
    assert len(logged_raw) >= emulated.produced - 1 - emulated.overwritten


def test_imu_temperature_once_a_second(logged):
    arrays, *_, columns = logged
    records = arrays.sensors[contract.IMU_TEMPERATURE.name]
    assert len(records) == pytest.approx(DRIVE_S, rel=0.02)
    assert np.median(np.diff(records["t_mono_ns"].astype(np.int64))) == pytest.approx(1e9, rel=0.02)
    assert np.array_equal(records["temperature_c"], 25.0 + records["temperature_raw"] / 16.0)
    held = np.unique(np.round((columns["imu_temperature_c"] - 25.0) * 16.0))
    assert set(records["temperature_raw"].tolist()) <= set(held.tolist())


def test_barometer_values_follow_the_datasheet(logged):
    arrays, *_ = logged
    records = arrays.sensors["/barometer"]
    assert len(records) > 200
    assert np.array_equal(records["pressure_pa"], records["pressure_raw"] / 4096.0 * 100.0)
    assert np.array_equal(records["temperature_c"], 42.5 + records["temperature_raw"] / 480.0)


def test_every_gps_sentence_and_fix(logged):
    arrays, _, devices, _ = logged
    logged_sentences = [s for r in arrays.json["/gps/nmea"] for s in r["sentences"]]
    assert logged_sentences == devices.gps.sent
    expected = []
    for sentence in devices.gps.sent:
        msg = pynmea2.parse(sentence)
        if msg.sentence_type == "GGA" and int(msg.gps_qual or 0) > 0:
            expected.append((msg.latitude, msg.longitude, float(msg.altitude)))
    fixes = arrays.json["/gps/fix"]
    assert [(f["latitude"], f["longitude"], f["altitude"]) for f in fixes] == expected
    # the receiver sends GST (the covariance) only once the logger's UBX-CFG-MSG has reached it
    known = [f["position_covariance_type"] == 2 for f in fixes]
    assert known == sorted(known) and known[-1]
    assert known.count(True) == sum(1 for s in devices.gps.sent if s[3:6] == "GST" and ",,,,,,,*" not in s)


def test_diagnostics_and_time_sync_every_second(logged):
    arrays, *_ = logged
    for topic in ("/diagnostics", "/time/sync"):
        times = np.array([r["t_mono_ns"] for r in arrays.json[topic]])
        assert len(times) >= DRIVE_S * 0.95
        assert np.median(np.diff(times)) == pytest.approx(1e9, rel=0.05)
    last = arrays.json["/diagnostics"][-1]
    assert {"can", "i2c", "gps"} <= set(last["sources"])
