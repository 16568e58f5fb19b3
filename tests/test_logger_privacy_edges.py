"""Privacy zones at the edges of NMEA: an epoch without a complete fix (GGA of quality 0, GGA
without altitude, a corrupt GGA beside a valid RMC) or with positions only in GLL, GNS or RMC must
not carry a position from inside a zone into ``/gps/nmea`` after an epoch outside."""

from __future__ import annotations

import asyncio
import functools
import json
import operator

import numpy as np
import pytest

from haulprofile import contract
from haulprofile.contract import privacy
from haulprofile.logger.clock import Clock
from haulprofile.logger.config import PrivacySection
from haulprofile.logger.privacy import Privacy
from haulprofile.logger.sources.gps import GpsSource

ZONE = {"name": "home", "lat": 48.1350, "lon": 11.5800, "radius_m": 150.0}
OUTSIDE = ("4807.8000", "N", "01134.5000", "E")  # 48.1300, 11.5750: ~680 m from the zone's centre
INSIDE = ("4808.1000", "N", "01134.8000", "E")  # the zone's centre
INSIDE_TEXT = ("4808.1000", "01134.8000")


def nmea(body: str) -> str:
    return f"${body}*{functools.reduce(operator.xor, body.encode(), 0):02X}"


def gga(utc, pos, quality=1, altitude="520.0"):
    return nmea(f"GPGGA,{utc},{','.join(pos)},{quality},08,0.9,{altitude},M,47.0,M,,")


def rmc(utc, pos):
    return nmea(f"GPRMC,{utc},A,{','.join(pos)},27.2,34.0,011226,,,A")


def corrupt(sentence: str) -> str:
    return sentence[:-2] + ("00" if sentence[-2:] != "00" else "11")


CASES = {
    "GGA of quality 0": lambda t: [gga(t, INSIDE, quality=0)],
    "GGA without altitude": lambda t: [gga(t, INSIDE, altitude="")],
    "corrupt GGA beside a valid RMC": lambda t: [corrupt(gga(t, INSIDE)), rmc(t, INSIDE)],
    "GLL only": lambda t: [nmea(f"GPGLL,{','.join(INSIDE)},{t},A,A")],
    "GNS only": lambda t: [nmea(f"GNGNS,{t},{','.join(INSIDE)},AN,10,0.9,520.0,47.0,,")],
    "RMC only": lambda t: [rmc(t, INSIDE)],
    "corrupt GGA alone": lambda t: [corrupt(gga(t, INSIDE))],
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_an_epoch_inside_without_a_complete_fix_writes_no_nmea(case):
    queue = asyncio.Queue(1000)
    source = GpsSource(queue, Clock(), "/dev/null", privacy=Privacy(PrivacySection(zones=[ZONE])))
    t_ns = 1_000_000_000
    for utc, lines in (("120000.00", [rmc("120000.00", OUTSIDE), gga("120000.00", OUTSIDE)]),
                       ("120001.00", CASES[case]("120001.00")),
                       ("120002.00", [rmc("120002.00", INSIDE), gga("120002.00", INSIDE)])):
        for line in lines:
            t_ns += 10_000_000
            source.handle_line(line.encode() + b"\r\n", t_ns)
    source.flush_epoch()
    source.flush_raw()
    written = []
    while not queue.empty():
        item = queue.get_nowait()
        written.append((item.topic.name, item.payload))
    nmea_lines = [s for topic, payload in written if topic == contract.GPS_NMEA.name
                  for s in json.loads(payload)["sentences"]]
    assert any(OUTSIDE[0] in s for s in nmea_lines), "the epoch outside is kept"
    assert not [s for s in nmea_lines if INSIDE_TEXT[0] in s or INSIDE_TEXT[1] in s]
    fixes = [json.loads(p) for topic, p in written if topic == contract.GPS_FIX.name]
    assert all(abs(f["latitude"] - 48.13) < 1e-3 for f in fixes)


VEHICLE_POSITION_PGN = 65267  # J1939-71: SPN 584/585, 1e-7 deg/bit, offset -210 deg


def decoded_positions(data):
    raw = np.ascontiguousarray(data).reshape(-1, 8).view("<u4").astype(float)
    return raw[:, 0] * 1e-7 - 210.0, raw[:, 1] * 1e-7 - 210.0


def position_frame(t_ns: int, lat: float, lon: float) -> tuple:
    raw = np.array([round((lat + 210.0) * 1e7), round((lon + 210.0) * 1e7)], "<u4").view(np.uint8)
    return (t_ns, (6 << 26) | (VEHICLE_POSITION_PGN << 8) | 0x1C, contract.CAN_FLAG_EXTENDED, 8, 0, 0, raw)


def test_redact_removes_j1939_vehicle_positions_recorded_in_a_zone(tmp_path):
    """The bus's own positions (PGN 65267), decodable with any J1939 DBC, once left the zone in
    ``/can/frames``; outside the zone they and the engine's frames stay as they were."""
    from haulprofile.analysis.redact import redact_bytes
    from haulprofile.contract.privacy import zones_from_tables
    from haulprofile.logger.writer import LogWriter

    source = tmp_path / "bus.mcap"
    lat = np.linspace(48.1300, 48.1400, 21)  # through the zone at 48.1350
    with open(source, "wb") as stream:
        writer = LogWriter(stream)
        for i, latitude in enumerate(lat):
            t = (i + 1) * 1_000_000_000
            writer.write_json(contract.GPS_FIX, contract.location_fix(t, t, latitude, 11.58, 520.0, 1.0, 2.0), t, t)
            engine = (t + 1, 0x0CF00400, contract.CAN_FLAG_EXTENDED, 8, 0, 0, np.arange(8, dtype=np.uint8))
            frames = np.array([position_frame(t + 2, latitude, 11.58), engine], contract.CAN_FRAME_DTYPE)
            writer.write(contract.CAN_FRAMES, contract.pack(contract.CAN_FRAMES, frames), t + 2, t + 2)
        writer.close()
    target = tmp_path / "redacted.mcap"
    with open(target, "wb") as stream:
        report = redact_bytes(source.read_bytes(), zones_from_tables([ZONE]), stream)
    from haulprofile.contract.reader import packed_records

    kept = np.concatenate(list(packed_records(target, contract.CAN_FRAMES)))
    positions = kept[kept["arbitration_id"] & 0x3FFFF00 == VEHICLE_POSITION_PGN << 8]
    lat_kept, lon_kept = decoded_positions(positions["data"])
    zones = zones_from_tables([ZONE])
    inside = sum(privacy.in_any(zones, a, 11.58) for a in lat)
    assert inside >= 3 and len(positions) <= len(lat) - inside
    assert not any(privacy.in_any(zones, a, b) for a, b in zip(lat_kept, lon_kept))
    assert len(positions) > 0 and report.messages_out > 0
    assert (kept["arbitration_id"] == 0x0CF00400).sum() == len(lat), "every engine frame kept"


def test_redact_decides_each_fix_of_a_burst_by_its_own_position(tmp_path):
    """A loaded logger reads several epochs from the serial port in one go and stamps them with one
    monotonic time. Where such a burst spans a zone's edge the fixes outside stay (byte for byte),
    those inside go, and the zone is entered and left once each."""
    from haulprofile.analysis.redact import redact_bytes
    from haulprofile.contract.privacy import zones_from_tables
    from haulprofile.logger.writer import LogWriter
    from mcap.reader import make_reader

    source = tmp_path / "burst.mcap"
    lat = np.linspace(48.1300, 48.1400, 41)  # through the zone at 48.1350
    zones = zones_from_tables([ZONE])
    inside = np.array([privacy.in_any(zones, a, 11.58) for a in lat])
    first_in, last_in = np.flatnonzero(inside)[[0, -1]]
    burst = {first_in - 3: first_in + 2, last_in - 2: last_in + 3}  # each burst stamped with one time
    stamps, t = [], 0
    for i in range(len(lat)):
        start = next((a for a, b in burst.items() if a < i <= b), None)
        t = t if start is not None else (i + 1) * 1_000_000_000
        stamps.append(t)
    with open(source, "wb") as stream:
        writer = LogWriter(stream)
        for latitude, t in zip(lat, stamps):
            writer.write_json(contract.GPS_FIX, contract.location_fix(t, t, latitude, 11.58, 520.0, 1.0, 2.0), t, t)
        writer.close()
    target = tmp_path / "redacted.mcap"
    with open(target, "wb") as stream:
        report = redact_bytes(source.read_bytes(), zones, stream)
    with open(target, "rb") as stream:
        kept = [(channel.topic, json.loads(message.data)) for _, channel, message in make_reader(stream).iter_messages()]
    fixes = [m["latitude"] for topic, m in kept if topic == contract.GPS_FIX.name]
    assert fixes == [float(a) for a, i in zip(lat, inside) if not i]
    assert report.fixes_removed == inside.sum()
    assert [m["event"] for topic, m in kept if topic == contract.PRIVACY_ZONE.name] == ["entered", "left"]


@pytest.mark.parametrize("fixes, inside_at_start, expected", [
    ([(1, False), (2, True), (3, True), (4, False)], False, [(2, 4)]),
    ([(1, True), (2, False), (3, True)], False, [(-np.inf, 2), (3, np.inf)]),  # inside before the first fix
    ([(1, False), (2, True)], True, [(-np.inf, 1), (2, np.inf)]),  # the file before ended inside
    ([(1, False), (2, False), (2, True), (3, False)], False, [(2, 3)]),  # one time, one fix inside
    ([], True, [(-np.inf, np.inf)]),
    ([], False, []),
])
def test_redact_stretches_in_zones(fixes, inside_at_start, expected):
    from haulprofile.analysis.redact import _stretches

    assert _stretches(fixes, inside_at_start) == expected
