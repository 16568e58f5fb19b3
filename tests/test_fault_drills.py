"""Fault drills: the real daemon against the emulators, with faults injected while it logs.

Each drill runs the daemon for a few seconds in real time, injects one fault, ends it, and then
reads every file back (a linear MCAP read, and the analysis side's `read_frames`). It checks that
the daemon survived (exit code 0, no source task stopped, still alive for the watchdog), that
`/diagnostics` in the log reports the fault, that the affected stream is logged again after the
fault ended, and that the other sources kept logging during the fault. No time or rate is judged
against a limit (a loaded machine would fail it): the recovery time of each drill (logged time
from the fault's end to the stream's first record after it) and the rates are printed
(``pytest -s``).

The IMU runs at 238 Hz here (its FIFO holds 134 ms): a shared CI machine may deschedule the I2C
thread for 100 ms, which the real sensor would survive at that rate too.
"""

from __future__ import annotations

import asyncio
import errno
import json
import os
import struct
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from haulprofile import contract
from haulprofile.logger.clock import Clock
from haulprofile.logger.config import Config
from haulprofile.logger.daemon import Daemon
from haulprofile.logger.emulators.faults import JumpingClock, faulty_devices
from haulprofile.logger.emulators.rig import emulation_config, run_daemon_for
from haulprofile.logger.emulators.signals import TimeSeries, synthetic_drive

FAULT_AT_S = 1.5
RECOVERY: dict[str, float] = {}


@dataclass
class Log:
    """What a linear read of the drill's files found: messages per topic and per-file health."""

    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)
    files: list[tuple[Path, bool]] = field(default_factory=list)

    def can(self, tx: bool = False) -> np.ndarray:
        parts = [contract.unpack(contract.CAN_FRAMES, data) for _, data in self.messages.get("/can/frames", [])]
        frames = np.concatenate(parts) if parts else np.zeros(0, contract.CAN_FRAME_DTYPE)
        is_tx = (frames["flags"] & contract.CAN_FLAG_TX) != 0
        return frames[is_tx == tx]

    def imu_ns(self) -> np.ndarray:
        parts = [contract.unpack(contract.IMU, data)["t_mono_ns"] for _, data in self.messages.get("/imu", [])]
        return np.sort(np.concatenate(parts).astype(np.int64)) if parts else np.zeros(0, np.int64)

    def json(self, topic: str) -> list[dict]:
        return [json.loads(data) for _, data in self.messages.get(topic, [])]

    def json_ns(self, topic: str) -> np.ndarray:
        """Sample times of a topic: JSON records, or packed sensor records (contract 2)."""
        if topic in contract.SENSOR_TOPICS:
            parts = [contract.unpack(contract.SENSOR_TOPICS[topic], data)["t_mono_ns"] for _, data in
                     self.messages.get(topic, [])]
            return np.sort(np.concatenate(parts).astype(np.int64)) if parts else np.zeros(0, np.int64)
        return np.sort(np.array([r["t_mono_ns"] for r in self.json(topic)], dtype=np.int64))

    def said(self) -> list[str]:
        return [line for record in self.json(contract.DIAGNOSTICS.name) for line in record["messages"]]


def read_log(paths: list[Path]) -> Log:
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader
    log = Log()
    for path in paths:
        topics, complete = {}, False
        with open(path, "rb") as stream:
            try:
                for record in StreamReader(stream, skip_magic=False).records:
                    if isinstance(record, Channel):
                        topics[record.id] = record.topic
                    elif isinstance(record, Message):
                        log.messages.setdefault(topics[record.channel_id], []).append((record.publish_time, record.data))
                complete = True
            except (McapError, EOFError, ValueError, struct.error) as exc:  # a cut file: complete chunks only
                print(f"{path.name}: linear read stopped at a cut ({exc!r})")
        log.files.append((path, complete))
    return log


@dataclass
class Drill:
    daemon: Daemon
    devices: object
    clock: Clock
    code: int
    marks: dict[str, int]
    log: Log

    def s(self, name: str) -> float:
        return self.marks[name] * 1e-9


def run_drill(tmp_path: Path, inject, duration_s: float = 6.0, configure=None, clock: Clock | None = None,
              restamp_can: bool = False, directory: Path | None = None, **device_kwargs) -> Drill:
    """Run the daemon with the emulators for ``duration_s``; ``await inject(daemon, devices, mark)``
    once it is logging. ``mark(name)`` notes the monotonic time of an event of the drill."""
    config = emulation_config(directory or tmp_path / "logs", 1.0, Config())
    config.i2c.lsm9ds1.odr_hz = 238.0
    if configure is not None:
        configure(config)
    clock = clock or Clock()
    devices = faulty_devices(TimeSeries(synthetic_drive(30.0)), clock, restamp_can=restamp_can,
                             **device_kwargs).start(config)
    daemon = Daemon(config, devices, clock)
    marks: dict[str, int] = {}

    def mark(name: str) -> None:
        marks[name] = clock.monotonic_ns()

    async def main():
        task = asyncio.create_task(run_daemon_for(daemon, devices, duration_s))
        await daemon.ready.wait()
        mark("start")
        await inject(daemon, devices, mark)
        marks["alive_after_drill"] = int(daemon.alive())
        return await task

    code = asyncio.run(main())
    files = sorted(Path(config.logger.directory).glob("*.mcap"))
    drill = Drill(daemon, devices, clock, code, marks, read_log(files))
    _check_survived(drill, files)
    return drill


def _check_survived(drill: Drill, files: list[Path]) -> None:
    from haulprofile.analysis.ingest.logs import read_frames
    assert drill.code == 0
    assert drill.marks["alive_after_drill"] == 1, "the watchdog would have stopped pinging"
    assert not [line for line in drill.log.said() if "stopped:" in line]
    assert files and all(path.stat().st_size > 0 for path in files)
    arrays = read_frames(files)  # the analysis side reads every file of the drill
    assert len(arrays.can) > 0


def recovery_s(stamps_ns: np.ndarray, end_ns: int) -> float:
    """Logged time from the end of a fault to the first record after it [s]."""
    after = stamps_ns[stamps_ns >= end_ns]
    assert len(after), "nothing logged after the fault ended"
    return (int(after[0]) - end_ns) * 1e-9


def count(stamps_ns: np.ndarray, start_ns: int, end_ns: int) -> int:
    return int(np.count_nonzero((stamps_ns >= start_ns) & (stamps_ns < end_ns)))


def rate_hz(stamps_ns: np.ndarray, start_ns: int, end_ns: int) -> float:
    return count(stamps_ns, start_ns, end_ns) / ((end_ns - start_ns) * 1e-9)


def assert_rates_kept(drill: Drill, streams: dict[str, np.ndarray], fault: tuple[str, str]) -> None:
    """Each stream was logged before and during the fault (rates printed, not judged)."""
    start, end = drill.marks[fault[0]], drill.marks[fault[1]]
    before_start = drill.marks["start"] + 300_000_000
    for name, stamps in streams.items():
        before, during = rate_hz(stamps, before_start, start), rate_hz(stamps, start, end)
        print(f"  {name}: {before:.1f} Hz before, {during:.1f} Hz during the fault")
        assert count(stamps, start, end) > 0 and count(stamps, before_start, start) > 0, name


def note(drill_name: str, seconds: float) -> None:
    RECOVERY[drill_name] = seconds
    print(f"recovery {drill_name}: {seconds:.3f} s")


def gap_end_after(stamps_ns: np.ndarray, end_ns: int, gap_ns: int = 300_000_000) -> float:
    """Where continuous logging resumed: the end of the last gap longer than ``gap_ns`` that
    starts before ``end_ns``, relative to ``end_ns`` [s] (0 if logging was back before)."""
    stamps = np.sort(stamps_ns)
    gaps = np.flatnonzero((np.diff(stamps) > gap_ns) & (stamps[:-1] < end_ns))
    if not len(gaps):
        return 0.0
    return max(0.0, (int(stamps[gaps[-1] + 1]) - end_ns) * 1e-9)


# --- I2C ----------------------------------------------------------------------------------------

def test_i2c_eio_nack_and_a_sensor_that_vanishes_and_returns(tmp_path):
    async def inject(daemon, devices, mark):
        await asyncio.sleep(FAULT_AT_S)
        bus = devices.faulty_i2c
        mark("fault")
        bus.fail(0x6B, errno.EIO, count=2)    # two bus errors on the IMU: counted, nothing lost for good
        bus.vanish(0x5F)                      # HTS221 stops acknowledging (NACK)
        bus.vanish(0x5C)                      # LPS25HB unplugged
        await asyncio.sleep(2.0)
        mark("end")
        bus.restore(0x5F)
        bus.restore(0x5C, power_cycle=True)   # back with its registers reset: must be configured again
        await asyncio.sleep(2.5)

    drill = run_drill(tmp_path, inject, duration_s=6.5)
    log, end = drill.log, drill.marks["end"]
    said = log.said()
    assert any("lsm9ds1: I2C error" in line and "Input/output error" in line for line in said)
    assert any(line.startswith("i2c: hts221: lost after") and "Remote I/O error" in line for line in said)
    assert any(line.startswith("i2c: lps25hb: lost after") for line in said)
    assert any("hts221: answers again" in line for line in said)
    assert any("lps25hb: answers again" in line for line in said)
    sensors = log.json(contract.DIAGNOSTICS.name)[-1]["sources"]["i2c"]
    assert sensors["lsm9ds1"]["errors"] >= 2 and sensors["hts221"]["errors"] >= 3
    assert sensors["lps25hb"]["state"] == sensors["hts221"]["state"] == "running"
    note("i2c NACK (HTS221 back)", recovery_s(log.json_ns("/humidity"), end))
    note("i2c sensor power-cycled (LPS25HB back)", recovery_s(log.json_ns("/barometer"), end))
    barometer = log.json_ns("/barometer")
    assert np.all(np.diff(barometer) > 0)
    assert_rates_kept(drill, {"imu": log.imu_ns(), "can": log.can()["t_mono_ns"].astype(np.int64),
                              "gps": log.json_ns("/gps/fix")}, ("fault", "end"))


# --- GPS ----------------------------------------------------------------------------------------

def test_gps_tty_closes_and_reopens(tmp_path):
    sent_before_unplug = []

    async def inject(daemon, devices, mark):
        await asyncio.sleep(FAULT_AT_S)
        mark("fault")
        devices.gps.unplug()
        sent_before_unplug.extend(devices.gps.sent)
        await asyncio.sleep(1.5)
        devices.gps.replug()
        mark("end")
        await asyncio.sleep(2.5)

    drill = run_drill(tmp_path, inject, duration_s=6.0, gps_link=tmp_path / "haulprofile-gps")
    log = drill.log
    said = log.said()
    assert any("gps: serial read error" in line for line in said)
    assert any("gps:" in line and "open again" in line for line in said)
    fixes = log.json_ns("/gps/fix")
    # while unplugged nothing new arrives: a fix read then (a busy loop may read the tty's last
    # bytes late) is of an epoch the receiver sent before it was unplugged
    last_time_of_day = max(s.split(",")[1] for s in sent_before_unplug if s[3:6] == "RMC")
    unplugged = [r for r in log.json("/gps/fix") if drill.marks["fault"] < r["t_mono_ns"] < drill.marks["end"]]
    assert all(_time_of_day(r["gps_time_utc_ns"]) <= last_time_of_day for r in unplugged)
    note("gps tty reopened", recovery_s(fixes, drill.marks["end"]))
    assert_rates_kept(drill, {"imu": log.imu_ns(), "can": log.can()["t_mono_ns"].astype(np.int64),
                              "barometer": log.json_ns("/barometer")}, ("fault", "end"))


def _time_of_day(utc_ns: int) -> str:
    """``hhmmss.ss`` of a UTC time [ns], as in RMC."""
    import datetime as dt
    seconds = dt.datetime.fromtimestamp(utc_ns // 1_000_000_000, dt.timezone.utc)
    return seconds.strftime("%H%M%S") + f".{utc_ns // 10_000_000 % 100:02d}"


def test_gps_garbage_and_half_sentences(tmp_path):
    rng = np.random.default_rng(3)
    noise = [
        b"\x00\xff\xb5\x62\x01\x07" + rng.integers(0, 256, 90, dtype=np.uint8).tobytes() + b"\r\n",
        b"$GPGGA,080001.00,4808.22000,N,011",                        # cut, the next sentence follows
        b"$GPRMC,080001.00,A,4808.22,N,01134.5,E,1.0,0.0,140524,,,A*00\r\n",   # wrong checksum
        b"$GPGGA,,,,*\r\n", b"GPGGA no dollar\r\n", b"$\r\n", b"*FF\r\n",
        b"$" + b"9" * 2000,                                            # a line far too long
        b"\r\n$PUBX,00,garbage*11\r\n",
    ]

    async def inject(daemon, devices, mark):
        await asyncio.sleep(FAULT_AT_S)
        mark("fault")
        for _ in range(10):
            for chunk in noise:
                devices.gps.write_raw(chunk)
            await asyncio.sleep(0.1)
        mark("end")
        await asyncio.sleep(3.0)

    drill = run_drill(tmp_path, inject, duration_s=6.0)
    log = drill.log
    gps = log.json(contract.DIAGNOSTICS.name)[-1]["sources"]["gps"]
    assert gps["bad_checksum"] >= 10 and gps["skipped"] >= 10 and gps["errors"] == 0
    fixes = log.json(contract.GPS_FIX.name)
    assert all(abs(f["latitude"] - 48.137) < 0.5 for f in fixes)  # no fix made of noise
    note("gps garbage", recovery_s(log.json_ns("/gps/fix"), drill.marks["end"]))
    assert_rates_kept(drill, {"gps": log.json_ns("/gps/fix"), "imu": log.imu_ns(),
                              "can": log.can()["t_mono_ns"].astype(np.int64)}, ("fault", "end"))


# --- CAN ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("mode", ["bus_off", "down"])
def test_can_bus_off_and_interface_down(tmp_path, mode):
    async def inject(daemon, devices, mark):
        await asyncio.sleep(FAULT_AT_S)
        mark("fault")
        setattr(devices.faulty_can, mode, True)
        await asyncio.sleep(2.0)
        setattr(devices.faulty_can, mode, False)
        mark("end")
        await asyncio.sleep(2.5)

    drill = run_drill(tmp_path, inject, duration_s=6.5)
    log = drill.log
    said = log.said()
    if mode == "bus_off":
        assert any("can: send failed" in line and "bus-off" in line for line in said)
        assert any("can: sending works again" in line for line in said)
    else:
        assert any("can: receive error" in line and "Network is down" in line for line in said)
        assert any("can: receiving again" in line for line in said)
    received = log.can()["t_mono_ns"].astype(np.int64)
    assert not np.any((received > drill.marks["fault"] + 300_000_000) & (received < drill.marks["end"]))
    note(f"can {mode} (frames)", recovery_s(received, drill.marks["end"]))
    note(f"can {mode} (OBD-II requests sent)", recovery_s(log.can(tx=True)["t_mono_ns"].astype(np.int64),
                                                         drill.marks["end"]))
    assert_rates_kept(drill, {"imu": log.imu_ns(), "gps": log.json_ns("/gps/fix"),
                              "barometer": log.json_ns("/barometer")}, ("fault", "end"))


def test_ecu_stops_answering(tmp_path):
    async def inject(daemon, devices, mark):
        await asyncio.sleep(FAULT_AT_S)
        mark("fault")
        devices.ecu.silent = True
        await asyncio.sleep(2.0)
        devices.ecu.silent = False
        mark("end")
        await asyncio.sleep(3.5)

    def configure(config):
        config.can.obd.failed_rounds_before_probe = 1  # 7 PIDs: probing after 7 unanswered requests

    drill = run_drill(tmp_path, inject, duration_s=7.5, configure=configure)
    log = drill.log
    said = log.said()
    assert any("no ECU answered" in line and "probing every 2 s" in line for line in said)
    assert any("an ECU answers OBD-II again" in line for line in said)
    frames = log.can()
    received = frames["t_mono_ns"].astype(np.int64)
    ids = frames["arbitration_id"].astype(np.int64)
    obd = received[(ids == 0x7E8) | ((ids & 0x1FFFFF00) == 0x18DAF100)]
    assert len(obd)
    note("ECU silent (broadcast back)", recovery_s(received, drill.marks["end"]))
    note("ECU silent (OBD-II answers back)", recovery_s(obd, drill.marks["end"]))
    assert_rates_kept(drill, {"imu": log.imu_ns(), "gps": log.json_ns("/gps/fix")}, ("fault", "end"))


# --- disk ---------------------------------------------------------------------------------------

def test_disk_full_by_the_free_space_probe(tmp_path):
    """A fake free-space probe (any machine): the watermark pauses writing and resumes it."""
    free = {"bytes": 10 ** 12}

    async def inject(daemon, devices, mark):
        daemon.storage.free_space_probe = lambda directory: free["bytes"]
        await asyncio.sleep(FAULT_AT_S)
        mark("fault")
        free["bytes"] = 100_000
        await asyncio.sleep(2.0)
        free["bytes"] = 10 ** 12
        mark("end")
        await asyncio.sleep(3.0)

    def configure(config):
        config.storage.on_low_space = "pause"

    drill = run_drill(tmp_path, inject, duration_s=7.0, configure=configure)
    log = drill.log
    said = log.said()
    assert any("writing paused" in line for line in said) and any("writing resumed" in line for line in said)
    assert len(log.files) == 2 and all(complete for _, complete in log.files)
    assert drill.daemon.diagnostics.paused_drops > 0
    received = log.can()["t_mono_ns"].astype(np.int64)
    note("disk full, fake probe (logging resumed)", gap_end_after(received, drill.marks["end"]))
    assert count(received, drill.marks["end"], received.max() + 1) > 0


def _mount_tmpfs(path: Path, size: str) -> bool:
    if os.geteuid() != 0:
        return False
    path.mkdir()
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                            capture_output=True)
    return result.returncode == 0


def test_disk_full_on_a_small_filesystem(tmp_path):
    """A real 3 MiB tmpfs filled up by another writer until ENOSPC (needs root and mount)."""
    small = tmp_path / "small"
    if not _mount_tmpfs(small, "3m"):
        pytest.skip("mounting a tmpfs needs root and mount permission; the free-space probe drill covers the logic")
    filler = small / "filler.bin"

    async def inject(daemon, devices, mark):
        await asyncio.sleep(FAULT_AT_S)
        mark("fault")
        with open(filler, "wb") as stream:
            try:
                while True:
                    stream.write(b"\0" * 65536)
                    stream.flush()
            except OSError as exc:
                assert exc.errno == errno.ENOSPC
        await asyncio.sleep(2.0)
        filler.unlink()
        mark("end")
        await asyncio.sleep(3.0)

    def configure(config):
        config.storage.on_low_space = "pause"
        config.storage.min_free_mb = 0.2
        config.storage.chunk_size_kb = 64

    try:
        drill = run_drill(tmp_path, inject, duration_s=7.0, configure=configure, directory=small / "logs")
        said = drill.log.said()
        assert any("writing paused" in line or "failed" in line for line in said)
        assert any("writing resumed" in line for line in said)
        received = drill.log.can()["t_mono_ns"].astype(np.int64)
        note("disk full, tmpfs ENOSPC (logging resumed)", gap_end_after(received, drill.marks["end"]))
    finally:
        subprocess.run(["umount", "-l", str(small)], capture_output=True)


# --- clocks -------------------------------------------------------------------------------------

def test_wall_clock_jump_when_gps_time_arrives(tmp_path):
    """The Pi boots with a stale wall clock; GPS (or NTP) sets it 400 days forward mid-drive.
    CAN receive stamps (wall clock, as the kernel's) stay right on the monotonic time base."""
    jump_ns = 400 * 86400 * 10 ** 9
    clock = JumpingClock()

    async def inject(daemon, devices, mark):
        await asyncio.sleep(FAULT_AT_S)
        mark("fault")
        clock.jump(jump_ns)
        mark("end")
        await asyncio.sleep(2.0)
        mark("later")
        await asyncio.sleep(1.0)

    drill = run_drill(tmp_path, inject, duration_s=5.0, clock=clock, restamp_can=True)
    log, jump_at = drill.log, drill.marks["end"]
    assert any("wall clock jumped by +34560000.000 s" in line for line in log.said())
    sync = log.json(contract.TIME_SYNC.name)
    mono = np.array([r["t_mono_ns"] for r in sync], dtype=np.int64)
    offset = np.array([r["t_realtime_ns"] - r["t_mono_ns"] for r in sync], dtype=np.int64)
    assert np.all(np.diff(mono) > 0)
    steps = np.flatnonzero(np.abs(np.diff(offset)) > 10 ** 9)
    assert len(steps) == 1 and abs(int(np.diff(offset)[steps[0]]) - jump_ns) < 10 ** 8
    note("wall clock jump (/time/sync shows it)", (int(mono[steps[0] + 1]) - jump_at) * 1e-9)
    received = log.can()["t_mono_ns"].astype(np.int64)
    published = np.array([t for t, _ in log.messages["/can/frames"]], dtype=np.int64)
    assert received.min() >= drill.marks["start"] - 10 ** 9 and received.max() <= published.max() + 10 ** 9
    note("wall clock jump (CAN stamps right)", recovery_s(received, jump_at))
    assert_rates_kept(drill, {"can": received, "imu": log.imu_ns(), "gps": log.json_ns("/gps/fix")},
                      ("end", "later"))


def test_print_recovery_times():
    """The closing note's table (run the module with ``-s``)."""
    for name, seconds in RECOVERY.items():
        print(f"{name:48s} {seconds:6.3f} s")
    assert all(np.isfinite(seconds) and seconds >= 0 for seconds in RECOVERY.values())
