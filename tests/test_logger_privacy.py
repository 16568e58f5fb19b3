"""Privacy zones and coarsening in the logger: the GPS emulator drives through a circle and a
polygon; not one coordinate, NMEA line or GPS time from inside is in the file, byte search of the
uncompressed MCAP included; coarsening leaves no full-precision position or wall-clock time."""

from __future__ import annotations

import asyncio
import datetime
import json
import re
import struct

import can
import numpy as np
import pynmea2
import pytest
from mcap.reader import make_reader

from haulprofile import contract
from haulprofile.contract import privacy
from haulprofile.logger import config as cfg
from haulprofile.logger.clock import Clock
from haulprofile.logger.config import CanSection, Config
from haulprofile.logger.emulators.rig import record_drive
from haulprofile.logger.sources.can import CanSource

ZONES = [
    {"name": "home", "lat": 48.1350, "lon": 11.5800, "radius_m": 150.0},
    {"name": "rest area", "polygon": [[48.1410, 11.5860], [48.1440, 11.5860], [48.1440, 11.5910],
                                      [48.1410, 11.5910]]},
]
DURATION_S = 16.0
TIME_SCALE = 4.0


def drive_signals() -> dict:
    """A straight diagonal drive, one new position every 0.1 s (no two epochs share a coordinate)."""
    t = np.arange(0.0, DURATION_S + 1.0, 0.05)
    return {"time_s": t, "latitude_deg": 48.1300 + t * 0.00095, "longitude_deg": 11.5750 + t * 0.00095,
            "altitude_m": 520.0 + t, "speed_mps": np.full_like(t, 140.0), "course_deg": np.full_like(t, 34.0)}


def privacy_config(**privacy_keys) -> Config:
    config = cfg.from_dict({"privacy": {"zones": ZONES, **privacy_keys}})
    config.can.enabled = False
    config.i2c.enabled = False
    config.storage.compression = "none"  # the byte search reads the file as it is on the disk
    return config


def read(path) -> dict[str, list]:
    out: dict[str, list] = {}
    with open(path, "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages():
            out.setdefault(channel.topic, []).append(message)
    return out


def inside_epochs(sent: list[str], zones) -> tuple[list, list]:
    """(inside, outside) RMC sentences the emulator sent, parsed."""
    inside, outside = [], []
    for sentence in sent:
        if sentence[3:6] == "RMC":
            msg = pynmea2.parse(sentence)
            if msg.latitude:
                (inside if privacy.in_any(zones, msg.latitude, msg.longitude) else outside).append(msg)
    return inside, outside


def needles(msg) -> list[bytes]:
    """Every form a coordinate or time of this epoch could take in the file."""
    lat, lon = msg.latitude, msg.longitude
    found = [msg.data[2].encode(), msg.data[4].encode(), msg.data[0].encode(),  # NMEA ddmm.mmmmm, hhmmss.ss
             repr(lat).encode(), repr(lon).encode(),  # JSON
             struct.pack("<d", lat), struct.pack("<d", lon), struct.pack("<f", lat), struct.pack("<f", lon)]
    return found


@pytest.fixture(scope="module")
def zoned(tmp_path_factory):
    path, daemon, devices = record_drive(drive_signals(), tmp_path_factory.mktemp("zoned"), duration_s=DURATION_S,
                                         time_scale=TIME_SCALE, config=privacy_config(), return_rig=True)
    return path, daemon, devices


def test_nothing_from_inside_a_zone_is_in_the_file(zoned):
    path, daemon, devices = zoned
    zones = privacy.zones_from_tables(ZONES)
    inside, outside = inside_epochs(devices.gps.sent, zones)
    assert len(inside) >= 20 and len(outside) >= 40
    raw = path.read_bytes()
    for msg in inside:
        for needle in needles(msg):
            assert needle not in raw, (msg, needle)
    # the search finds what it looks for: epochs outside are there in every text form
    found = sum(all(n in raw for n in needles(msg)[:5]) for msg in outside)
    assert found >= len(outside) - 3  # the last epochs may have been in flight at the stop
    messages = read(path)
    fixes = [json.loads(m.data) for m in messages["/gps/fix"]]
    assert fixes and not any(privacy.in_any(zones, f["latitude"], f["longitude"]) for f in fixes)
    stretches = _stretches(sorted(_utc_ns(m) for m in inside))
    assert len(stretches) == 2
    for record in (json.loads(m.data) for m in messages["/time/sync"]):
        gps_ns = record["gps_time_utc_ns"]
        if gps_ns is not None:  # extrapolated from the last fix written, which is outside, at most
            # to the next epoch, which may be the first inside (judged when the one after begins)
            assert not any(start < gps_ns <= end for start, end in stretches)
    lines = [s for m in messages["/gps/nmea"] for s in json.loads(m.data)["sentences"]]
    assert lines and not any(s in lines for s in devices.gps.sent if s[3:6] in ("RMC", "GGA")
                             and privacy.in_any(zones, *_lat_lon(s)))
    markers = [json.loads(m.data) for m in messages["/privacy/zone"]]
    assert [m["event"] for m in markers] == ["entered", "left", "entered", "left"]
    gps = next(s for s in daemon.sources if s.name == "gps")
    assert gps.stats.extra["zone_epochs"] == pytest.approx(len(inside), abs=2)


def _utc_ns(msg) -> int:
    return int(datetime.datetime.combine(msg.datestamp, msg.timestamp).replace(
        tzinfo=datetime.timezone.utc).timestamp() * 1e9)


def _stretches(times_ns: list[int]) -> list[tuple[int, int]]:
    out = [[times_ns[0], times_ns[0]]]
    for t in times_ns[1:]:
        if t - out[-1][1] > 150_000_000:
            out.append([t, t])
        out[-1][1] = t
    return [tuple(s) for s in out]


def _lat_lon(sentence: str) -> tuple[float, float]:
    msg = pynmea2.parse(sentence)
    return (msg.latitude, msg.longitude) if msg.latitude else (0.0, 0.0)


def test_coarsened_positions_and_wall_clock(tmp_path):
    grid_m, resolution_s = 250.0, 60.0
    path = record_drive(drive_signals(), tmp_path, duration_s=8.0, time_scale=TIME_SCALE,
                        config=privacy_config(position_grid_m=grid_m, time_resolution_s=resolution_s))
    assert int(re.search(r"_(\d{8}T\d{6})Z_", path.name)[1][-2:]) == 0  # file name to the minute
    messages = read(path)
    assert "/gps/nmea" not in messages  # raw NMEA would carry full positions and times
    fixes = [json.loads(m.data) for m in messages["/gps/fix"]]
    assert len(fixes) > 10
    for fix in fixes:
        assert privacy.snap_position(fix["latitude"], fix["longitude"], grid_m) == pytest.approx(
            (fix["latitude"], fix["longitude"]), abs=1e-12)
        assert (fix["gps_time_utc_ns"] - fix["t_mono_ns"]) % int(resolution_s * 1e9) == 0
    assert len({(f["latitude"], f["longitude"]) for f in fixes}) < len(fixes) / 4
    offsets = set()
    for topic, items in messages.items():
        for m in items:
            assert (m.log_time - m.publish_time) % int(resolution_s * 1e9) == 0, topic
            offsets.add(m.log_time - m.publish_time)
    assert len(offsets) == 1  # one rounded offset: many records do not narrow it down
    for record in (json.loads(m.data) for m in messages["/time/sync"]):
        assert (record["t_realtime_ns"] - record["t_mono_ns"]) % int(resolution_s * 1e9) == 0


def test_vehicle_position_and_time_pgns_from_the_bus_are_not_logged():
    """A telematics unit's J1939 VP (65267) and TD (65254) would carry what the zones withhold."""
    channel = "privacy-vp"
    player = can.Bus(interface="virtual", channel=channel)
    logger_bus = can.Bus(interface="virtual", channel=channel)
    section = CanSection(interface="virtual")
    vp, td, eec1 = 0x18FEF317, 0x18FEE617, 0x0CF00400

    async def main():
        queue = asyncio.Queue(1000)
        source = CanSource(queue, Clock(), section, logger_bus, drop_pgns=Config().privacy.drop_can_pgns)
        task = asyncio.create_task(source.run())
        for arb in (vp, td, eec1, vp):
            player.send(can.Message(arbitration_id=arb, data=bytes(range(8)), is_extended_id=True))
        await asyncio.sleep(0.3)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await source.close()
        return source, b"".join(queue.get_nowait().payload for _ in range(queue.qsize()))

    source, payload = asyncio.run(main())
    player.shutdown()
    frames = contract.unpack(contract.CAN_FRAMES, payload)
    assert frames["arbitration_id"].tolist() == [eec1]
    assert source.stats.extra["privacy_dropped"] == 3


@pytest.mark.parametrize("privacy_keys, message", [
    ({"zones": [{"lat": 48.0, "lon": 11.0}]}, "privacy.zones[0]: a circle needs lat, lon and radius_m"),
    ({"zones": [{"lat": 48.0, "lon": 11.0, "radius_m": -1}]}, "privacy.zones[0].radius_m must be > 0"),
    ({"zones": [{"polygon": [[48.0, 11.0], [48.1, 11.0]]}]}, "at least 3 [lat, lon] pairs"),
    ({"zones": [{"lat": 95.0, "lon": 11.0, "radius_m": 5}]}, "not a latitude/longitude"),
    ({"zones": [{"lat": 48.0, "lon": 11.0, "radius_m": 5, "polygon": []}]}, "not both"),
    ({"zones": [{"lat": 48.0, "lon": 11.0, "radius": 5}]}, "unknown key radius"),
    ({"position_grid_m": -5}, "privacy.position_grid_m must be >= 0"),
])
def test_bad_zones_are_one_line_errors(privacy_keys, message):
    with pytest.raises(cfg.ConfigError, match=re.escape(message)):
        cfg.from_dict({"privacy": privacy_keys})


def test_zone_geometry():
    circle, square = privacy.zones_from_tables(ZONES)
    assert circle.contains(48.1350, 11.5800) and circle.contains(48.1350 + 140 / 111_195, 11.5800)
    assert not circle.contains(48.1350 + 160 / 111_195, 11.5800)
    assert square.contains(48.1425, 11.5885) and not square.contains(48.1445, 11.5885)
    assert not square.contains(48.1425, 11.5855)
    lat, lon = privacy.snap_position(48.13712, 11.57534, 100.0)
    assert privacy.distance_m(lat, lon, 48.13712, 11.57534) < 100.0 * 0.71
    clock = privacy.CoarseClock(60_000_000_000)
    base = 1_715_673_599_950_000_000  # 50 ms before a minute
    offsets = {clock(base + k * 10**9 + jitter, k * 10**9) - k * 10**9 for k, jitter in
               enumerate([0, 80_000_000, -30_000_000, 90_000_000] * 5)}
    assert len(offsets) == 1  # arrival jitter across a minute edge does not flip the rounded offset
    assert clock(base + 3600 * 10**9, 0) - base > 3500 * 10**9  # a clock step moves it
