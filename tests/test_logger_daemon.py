"""The daemon in real time at the logger's rates, a missing sensor, and the systemd notify protocol.

The real-time run uses the LSM9DS1 at 238 Hz (its 32-slot FIFO then holds 134 ms, the LPS25HB's
1.28 s): this machine is shared with other test runs, and a scheduling gap of 100 ms would
overflow the FIFO at 952 Hz just as it would on the real sensor. The 952 Hz path is tested with
late reads on a stepped clock (``tests/test_i2c_sensors.py``); that it loses nothing at full load
is the benchmark's measurement (``tools/benchmarks/logger.py``).
"""

from __future__ import annotations

import asyncio
import os
import socket

import numpy as np
import pytest

from haulprofile import contract
from haulprofile.logger.clock import Clock
from haulprofile.logger.config import Config
from haulprofile.logger.daemon import Daemon
from haulprofile.logger.emulators.rig import EmulatedDevices, emulation_config, record_drive, run_daemon_for
from haulprofile.logger.emulators.signals import TimeSeries, synthetic_drive

from test_logger_crash import read_linear


@pytest.fixture(scope="module")
def full_rate(tmp_path_factory):
    out = tmp_path_factory.mktemp("full-rate")
    config = Config()
    config.i2c.lsm9ds1.odr_hz = 238.0
    return record_drive(synthetic_drive(30.0), out, duration_s=4.0, config=config, return_rig=True)


def _messages(path):
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader
    topics, out = {}, {}
    with open(path, "rb") as stream:
        for record in StreamReader(stream).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Message):
                out.setdefault(topics[record.channel_id], []).append(record.data)
    return out


def test_full_rates_in_real_time_lose_nothing(full_rate):
    path, daemon, devices = full_rate
    messages = _messages(path)
    imu = np.concatenate([contract.unpack(contract.IMU, m) for m in messages["/imu"]])
    model = devices.board.models["lsm9ds1"]
    assert model.overwritten == 0 and len(imu) == len(model.served) >= 3.5 * 238
    served = np.frombuffer(b"".join(model.served), dtype="<i2").reshape(-1, 6)
    assert np.array_equal(imu["accel_raw"], served[:, 3:])
    baro = np.concatenate([contract.unpack(contract.BAROMETER, m) for m in messages["/barometer"]])
    assert list(zip(baro["pressure_raw"].tolist(), baro["temperature_raw"].tolist())) == \
        devices.board.models["lps25hb"].served
    assert len(baro) >= 3.5 * 25
    humidity = np.concatenate([contract.unpack(contract.HUMIDITY, m) for m in messages["/humidity"]])
    assert len(humidity) == len(devices.board.models["hts221"].served) >= 3.5 * 12.5
    frames = np.concatenate([contract.unpack(contract.CAN_FRAMES, m) for m in messages["/can/frames"]])
    assert (frames["flags"] & contract.CAN_FLAG_TX == 0).sum() == len(devices.ecu.sent)
    assert all(s.stats.drops == 0 for s in daemon.sources)


def test_file_is_closed_with_summary_and_metadata(full_rate):
    from mcap.reader import make_reader
    path, daemon, _ = full_rate
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert summary.statistics.message_count == sum(1 for _ in iter_all(path))
    assert metadata["haulprofile.logger"]["boot_id"] == daemon.storage.boot_id
    imu_channel = next(c for c in summary.channels.values() if c.topic == "/imu")
    assert float(imu_channel.metadata["accel_scale_mps2_per_lsb"]) == pytest.approx(0.122e-3 * 9.80665)
    assert path.name.startswith(f"haulprofile_{daemon.storage.boot_id}_")


def iter_all(path):
    from mcap.records import Message
    from mcap.stream_reader import StreamReader
    with open(path, "rb") as stream:
        for record in StreamReader(stream).records:
            if isinstance(record, Message):
                yield record


def _run(tmp_path, duration_s: float, missing=(), notify_path=None, during=None):
    config = emulation_config(tmp_path / "logs", 1.0, Config())
    clock = Clock()
    devices = EmulatedDevices(TimeSeries(synthetic_drive(30.0)), clock, missing_sensors=missing).start(config)
    if notify_path is not None:
        os.environ["NOTIFY_SOCKET"] = str(notify_path)
    try:
        daemon = Daemon(config, devices, clock)
    finally:
        os.environ.pop("NOTIFY_SOCKET", None)

    async def main():
        if during is None:
            return await run_daemon_for(daemon, devices, duration_s)
        task = asyncio.create_task(run_daemon_for(daemon, devices, duration_s))
        await daemon.ready.wait()
        await during(daemon)
        return await task

    code = asyncio.run(main())
    return daemon, code


def test_a_missing_sensor_is_a_warning_and_the_rest_keeps_logging(tmp_path):
    daemon, code = _run(tmp_path, 1.5, missing=("hts221",))
    assert code == 0
    counts, _, complete = read_linear(daemon.storage.files_written[0])
    assert complete and "/humidity" not in counts
    assert counts["/barometer"] > 0 and counts["/imu"] > 0 and counts["/can/frames"] > 0
    import json
    diagnostics = [json.loads(m.data) for m in iter_all(daemon.storage.files_written[0])
                   if m.data.startswith(b'{"t_mono_ns"') and b'"sources"' in m.data]
    said = [line for d in diagnostics for line in d["messages"]]
    assert any("hts221" in line and "does not answer" in line for line in said)


def test_systemd_ready_and_watchdog_only_while_alive(tmp_path):
    notify_path = tmp_path / "notify.sock"
    server = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    server.bind(str(notify_path))
    server.setblocking(False)

    async def kill_the_i2c_thread(daemon):
        await asyncio.sleep(1.6)
        i2c = next(s for s in daemon.sources if s.name == "i2c")
        i2c.stop_thread()
        await asyncio.sleep(1.5)
        assert not daemon.alive()
        daemon.notifier.sent.append("--- i2c dead ---")

    daemon, code = _run(tmp_path, 3.5, notify_path=notify_path, during=kill_the_i2c_thread)
    received = []
    while True:
        try:
            received.append(server.recv(4096).decode())
        except BlockingIOError:
            break
    server.close()
    assert received[0].startswith("READY=1")
    assert any(r.startswith("WATCHDOG=1") for r in received)
    sent = daemon.notifier.sent
    dead_at = sent.index("--- i2c dead ---")
    assert any(s.startswith("WATCHDOG=1") for s in sent[:dead_at])
    assert not any(s.startswith("WATCHDOG=1") for s in sent[dead_at:])


def test_no_notify_socket_means_no_notifications(full_rate):
    _, daemon, _ = full_rate
    assert daemon.notifier.sent == []


def test_a_logged_drive_reports_its_progress(tmp_path):
    """`record_drive`'s progress callback (the demo's progress line): the drive advances, the
    CAN frames add up, nothing is reported past the end."""
    seen = []
    record_drive(synthetic_drive(30.0), tmp_path, duration_s=20.0, time_scale=10.0, progress=seen.append,
                 progress_every_s=0.2)
    assert len(seen) >= 2
    driven = [p.driven_s for p in seen]
    frames = [p.can_frames for p in seen]
    assert driven == sorted(driven) and driven[0] < driven[-1] <= 20.0
    assert frames == sorted(frames) and frames[-1] > 0
    assert all(p.duration_s == 20.0 for p in seen)
