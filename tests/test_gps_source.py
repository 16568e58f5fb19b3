"""GPS source on real receiver output (``tests/data/real-gps``) written into a pseudo-terminal that
the real serial source opens by path; references computed with pynmea2 and pyubx2."""

from __future__ import annotations

import asyncio
import json
import math
import os
import tty

import pynmea2
import pytest

from haulprofile import contract
from haulprofile.logger.clock import Clock
from haulprofile.logger.emulators.gps import epoch_sentences, with_checksum
from haulprofile.contract.nmea import nmea_checksum_ok
from haulprofile.logger.sources.gps import GpsSource, ubx_cfg_rate


def through_pty(data: bytes, configure_rate_hz: float | None = None, request_accuracy: bool = False):
    """Feed ``data`` through a pty into a GpsSource; returns (source, items, bytes the source wrote)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    written = bytearray()

    async def main():
        queue = asyncio.Queue(10_000)
        source = GpsSource(queue, Clock(), port, 9600, configure_rate_hz, request_accuracy=request_accuracy)
        source.open()
        task = asyncio.create_task(source.run())
        await asyncio.sleep(0.05)
        for i in range(0, len(data), 256):
            os.write(master, data[i:i + 256])
            await asyncio.sleep(0.002)
        await asyncio.sleep(0.2)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await source.close()
        while True:
            try:
                chunk = os.read(master, 4096) if _readable(master) else b""
            except OSError:
                break
            if not chunk:
                break
            written.extend(chunk)
        return source, [queue.get_nowait() for _ in range(queue.qsize())]

    try:
        source, items = asyncio.run(main())
    finally:
        os.close(master)
        os.close(slave)
    return source, items, bytes(written)


def _readable(fd) -> bool:
    import select
    return bool(select.select([fd], [], [], 0.05)[0])


def _fixes(items):
    return [json.loads(i.payload) for i in items if i.topic is contract.GPS_FIX]


def _raw(items):
    return [s for i in items if i.topic is contract.GPS_NMEA for s in json.loads(i.payload)["sentences"]]


def _reference(data: bytes):
    """pynmea2's view of the stream: parsed sentences and the number of checksum failures."""
    parsed, bad = [], 0
    for line in data.split(b"\n"):
        text = line.decode("ascii", errors="replace").strip()
        if "$" not in text:
            continue
        text = text[text.index("$"):]
        try:
            parsed.append(pynmea2.parse(text, check=True))
        except pynmea2.ChecksumError:
            bad += 1
        except pynmea2.ParseError:
            pass
    return parsed, bad


def test_ublox7_power_up_stream(data_dir):
    data = (data_dir / "real-gps" / "pynmeagps-pygpsdata-nmea2.log").read_bytes()
    source, items, _ = through_pty(data)
    parsed, bad = _reference(data)
    gga = [m for m in parsed if getattr(m, "sentence_type", "") == "GGA" and int(m.gps_qual or 0) > 0]
    fixes = _fixes(items)
    assert len(fixes) == len(gga) >= 1
    assert fixes[0]["latitude"] == gga[0].latitude
    assert fixes[0]["longitude"] == gga[0].longitude < 0
    assert fixes[0]["altitude"] == float(gga[0].altitude)
    rmc = next(m for m in parsed if getattr(m, "sentence_type", "") == "RMC")
    assert fixes[0]["speed_mps"] == pytest.approx(float(rmc.spd_over_grnd) * 1852 / 3600)
    assert fixes[0]["gps_time_utc_ns"] is not None
    # no GST at power-up: the fix keeps the geometry the analysis takes an accuracy from
    gsa = next(m for m in parsed if getattr(m, "sentence_type", "") == "GSA")
    assert fixes[0]["v_acc_m"] is None
    assert (fixes[0]["hdop"], fixes[0]["vdop"]) == (float(gga[0].horizontal_dil), float(gsa.vdop)) == (1.16, 2.05)
    assert len(_raw(items)) == sum(1 for line in data.split(b"\n") if b"$" in line)
    assert source.stats.extra["bad_checksum"] == bad == 0


@pytest.mark.parametrize("name", ["pynmeagps-pygpsdata-nmeabadck.log", "pyubx2-pygpsdata-BADCK2.log",
                                  "pyubx2-pygpsdata-NMEABADEND.log"])
def test_bad_checksums_and_truncated_lines_are_counted_not_fatal(data_dir, name):
    data = (data_dir / "real-gps" / name).read_bytes()
    source, items, _ = through_pty(data)
    _, bad = _reference(data)
    assert source.stats.state == "running"
    assert source.stats.extra["bad_checksum"] >= bad
    assert source.stats.extra["bad_checksum"] > 0


@pytest.mark.parametrize("name", ["pynmeagps-trimble_nmea.log", "pyubx2-pygpsdata-MIXED.log",
                                  "pynmeagps-pygpsdata-mixed.log", "pynmeagps-pygpsdata-nmeastartup.log",
                                  "pynmeagps-pygpsdata-nmea4.log", "pyubx2-pygpsdata-NMEA.log"])
def test_proprietary_sentences_and_binary_ubx_are_skipped(data_dir, name):
    data = (data_dir / "real-gps" / name).read_bytes()
    source, items, _ = through_pty(data)
    parsed, _ = _reference(data)
    gga = [m for m in parsed if getattr(m, "sentence_type", "") == "GGA" and int(m.gps_qual or 0) > 0 and m.altitude is not None]
    assert source.stats.state == "running"
    assert len(_fixes(items)) == len({m.timestamp for m in gga})


def test_gst_gives_horizontal_and_vertical_accuracy(data_dir):
    data = (data_dir / "real-gps" / "pyubx2-pygpsdata-MIXED2.log").read_bytes()
    source, items, _ = through_pty(data)
    parsed, _ = _reference(data)
    gst = next(m for m in parsed if getattr(m, "sentence_type", "") == "GST")
    fix = next(f for f in _fixes(items) if f["h_acc_m"] is not None)
    assert fix["h_acc_m"] == math.hypot(float(gst.std_dev_latitude), float(gst.std_dev_longitude))
    assert fix["v_acc_m"] == float(gst.std_dev_altitude)
    # foxglove.LocationFix: covariance in east, north, up; GST's longitude sigma is east, latitude north
    assert float(gst.std_dev_latitude) != float(gst.std_dev_longitude)
    assert fix["position_covariance"][0] == float(gst.std_dev_longitude) ** 2
    assert fix["position_covariance"][4] == float(gst.std_dev_latitude) ** 2
    assert fix["position_covariance"][8] == fix["v_acc_m"] ** 2
    assert fix["position_covariance_type"] == 2


def test_startup_rate_configuration_is_a_valid_ubx_cfg_rate():
    pyubx2 = pytest.importorskip("pyubx2")
    message = pyubx2.UBXReader.parse(ubx_cfg_rate(10.0))
    assert message.identity == "CFG-RATE"
    assert message.measRate == 100 and message.navRate == 1 and message.timeRef == 1
    _, _, written = through_pty(b"", configure_rate_hz=10.0)
    assert written == ubx_cfg_rate(10.0)


def test_checksum_agrees_with_pynmea2(data_dir):
    import datetime as dt
    sentences = epoch_sentences(dt.datetime(2024, 5, 14, 8, 0, 1, 100000),
                                {"latitude_deg": -33.8688, "longitude_deg": 151.2093, "altitude_m": 58.0,
                                 "speed_mps": 12.5, "course_deg": 271.0, "h_acc_m": 1.8, "v_acc_m": 3.1})
    lines = [line.decode("ascii", "replace").strip()
             for name in ("pynmeagps-pygpsdata-nmeabadck.log", "pyubx2-pygpsdata-BADCK2.log")
             for line in (data_dir / "real-gps" / name).read_bytes().split(b"\n") if line.startswith(b"$")]
    for sentence in sentences + lines:
        try:
            pynmea2.parse(sentence, check=True)
            valid = True
        except pynmea2.ChecksumError:
            valid = False
        except pynmea2.ParseError:
            continue
        assert nmea_checksum_ok(sentence) == valid, sentence
    assert nmea_checksum_ok(with_checksum("GPGGA,1,2,3"))


def test_unplugged_receiver_is_one_error_and_a_reopen_loop_not_a_busy_loop():
    master, slave = os.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    said = []

    async def main():
        source = GpsSource(asyncio.Queue(100), Clock(), port, 9600, say=said.append)
        source.open()
        task = asyncio.create_task(source.run())
        os.write(master, b"$GPTXT,01,01,02,u-blox ag - www.u-blox.com*50\r\n")
        await asyncio.sleep(0.1)
        os.close(master)
        os.close(slave)
        await asyncio.sleep(0.5)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await source.close()
        return source

    source = asyncio.run(main())
    assert source.stats.state == "port lost"
    assert source.stats.errors == 1 and len(said) == 1 and "reopening" in said[0]
    assert source.stats.extra["lines"] == 1


def test_the_source_asks_a_u_blox_for_gst_which_it_sends_only_from_then_on():
    """A u-blox 7 sends no GST by default (`tests/data/real-gps`'s u-blox 7 at power-up: TXT, RMC,
    VTG, GGA, GSA, GSV, GLL), so the fixes had no vertical accuracy and the gradient no GPS
    altitude: the source asks for it with UBX-CFG-MSG at opening; the emulated receiver, as the
    real one, sends GST only once asked, and forgets it when unplugged."""
    import time

    import numpy as np

    from haulprofile.logger.emulators.gps import GpsEmulator, gst_rate
    from haulprofile.logger.emulators.signals import TimeSeries
    from haulprofile.logger.sources.gps import NMEA_GST, ubx_cfg_msg

    pyubx2 = pytest.importorskip("pyubx2")
    message = pyubx2.UBXReader.parse(ubx_cfg_msg(*NMEA_GST, 1))
    # the 3-byte form sets the rate on the port it arrives on (pyubx2 names that field rateDDC)
    assert message.identity == "CFG-MSG" and (message.msgClass, message.msgID, message.rateDDC) == (0xF0, 0x07, 1)
    assert gst_rate(b"") == 0 and gst_rate(ubx_cfg_msg(*NMEA_GST, 1)) == 1
    assert gst_rate(ubx_cfg_msg(*NMEA_GST, 1) + ubx_cfg_msg(*NMEA_GST, 0)) == 0
    _, _, written = through_pty(b"", request_accuracy=True)
    assert written == ubx_cfg_msg(*NMEA_GST, 1)

    clock = Clock()
    signals = TimeSeries({"time_s": np.array([0.0, 100.0]), "v_acc_m": np.array([3.5, 3.5]),
                          "h_acc_m": np.array([2.0, 2.0])})
    emulator = GpsEmulator(signals, clock, clock.monotonic_ns(), rate_hz=20.0).start()
    try:
        deadline = time.monotonic() + 10.0
        while len(emulator.sent) < 12 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert emulator.sent and not any("GST" in s for s in emulator.sent)
        fixes = []

        async def main():
            queue = asyncio.Queue(10_000)
            source = GpsSource(queue, Clock(), emulator.port, 9600, request_accuracy=True)
            source.open()
            task = asyncio.create_task(source.run())
            for _ in range(300):
                await asyncio.sleep(0.02)
                while not queue.empty():
                    item = queue.get_nowait()
                    if item.topic is contract.GPS_FIX:
                        fixes.append(json.loads(item.payload))
                if sum(1 for fix in fixes if fix["v_acc_m"] is not None) >= 3:
                    break
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            await source.close()

        asyncio.run(main())
        accuracies = [fix["v_acc_m"] for fix in fixes]
        assert accuracies.count(3.5) >= 3
        emulator.unplug()
        emulator.replug()
        assert gst_rate(bytes(emulator.received[emulator._configured_from:])) == 0
    finally:
        emulator.stop()
        emulator.close()
