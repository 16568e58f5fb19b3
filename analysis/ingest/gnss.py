"""GPS-only logs: a receiver's raw NMEA 0183 and u-blox UBX output as ``/gps/fix`` records.

NMEA goes through the logger's own epoch assembly (`haulprofile.contract.nmea`, pynmea2), so a
file gives the very fixes the logger would have logged from the same bytes: sentences of one
epoch merged (GGA position, RMC/VTG speed, GST accuracy), bad checksums and proprietary sentences
skipped. UBX NAV-PVT messages (pyubx2) give fixes of their own. A fix's time is its UTC (RMC date
and time, or NAV-PVT's); without a date, the UTC time of day. Those times stand in for the
monotonic clock (``t_mono_ns``): a GPS-only log has no other.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

from haulprofile import contract

NMEA_START = (b"$GP", b"$GN", b"$GL", b"$GA", b"$GB", b"$BD", b"$GQ", b"$P")
UBX_SYNC = b"\xb5\x62"
DAY_NS = 86_400 * 1_000_000_000


def looks_like_gnss(head: bytes) -> bool:
    """True if the first bytes of a file are NMEA sentences with valid checksums, or UBX frames."""
    from haulprofile.contract.nmea import nmea_checksum_ok

    lines = head.split(b"\n")
    lines = [line.strip() for line in (lines[:-1] if len(head) >= 4096 else lines) if line.strip()]
    nmea = [line for line in lines if line.startswith(NMEA_START) and b"*" in line[-4:]]
    if 2 * len(nmea) >= len(lines) and any(nmea_checksum_ok(line.decode("ascii", "replace")) for line in nmea):
        return True
    position = head.find(UBX_SYNC)
    while 0 <= position < len(head) - 8:
        if _ubx_frame_ok(head[position:]):
            return True
        position = head.find(UBX_SYNC, position + 1)
    return False


def _ubx_frame_ok(data: bytes) -> bool:
    """The UBX frame at the start of ``data`` is whole and its Fletcher checksum holds."""
    if len(data) < 8:
        return False
    length = int.from_bytes(data[4:6], "little")
    if len(data) < 8 + length:
        return False
    ck_a = ck_b = 0
    for byte in data[2:6 + length]:
        ck_a = (ck_a + byte) & 0xFF
        ck_b = (ck_b + ck_a) & 0xFF
    return data[6 + length:8 + length] == bytes([ck_a, ck_b])


def read_fixes(path: str | Path) -> list[dict]:
    """``/gps/fix`` records of a raw receiver log, in time order; NMEA's or UBX NAV-PVT's,
    whichever gives more (a receiver may send both)."""
    data = Path(path).read_bytes()
    nmea = _nmea_fixes(data)
    ubx = _ubx_fixes(data) if UBX_SYNC in data else []
    fixes = ubx if len(ubx) > len(nmea) else nmea
    return sorted(fixes, key=lambda f: f["t_mono_ns"])


def _nmea_fixes(data: bytes) -> list[dict]:
    """Fixes of the NMEA sentences, timed by their UTC (or UTC time of day, rolling over at midnight)."""
    from haulprofile.contract.nmea import EpochFixes

    fixes: list[tuple[str, dict]] = []
    epochs = EpochFixes(lambda epoch, fix: fixes.append((epoch.time_key, fix)), {})
    for line in data.split(b"\n"):
        start = line.find(b"$")
        if start >= 0:
            epochs.sentence(line[start:].rstrip(b"\r").decode("ascii", errors="replace"), 0)
    epochs.flush()
    out, day_ns, last = [], 0, None
    for time_key, fix in fixes:
        if fix.get("gps_time_utc_ns") is not None:
            t = fix["gps_time_utc_ns"]
        else:
            time_of_day = dt.time.fromisoformat(time_key)
            t = ((time_of_day.hour * 60 + time_of_day.minute) * 60 + time_of_day.second) * 1_000_000_000 \
                + time_of_day.microsecond * 1000
            if last is not None and t + day_ns < last - DAY_NS // 2:
                day_ns += DAY_NS
            t += day_ns
        last = t
        fix["t_mono_ns"] = t
        out.append(fix)
    return out


def _ubx_fixes(data: bytes) -> list[dict]:
    """Fixes of the valid NAV-PVT messages (date and time valid, a 2D or 3D fix)."""
    import io

    try:
        from pyubx2 import UBX_PROTOCOL, UBXReader
    except ImportError:
        from ..errors import UserError

        raise UserError("reading u-blox UBX logs needs pyubx2 (pip install pyubx2)") from None
    fixes = []
    for _raw, msg in UBXReader(io.BytesIO(data), protfilter=UBX_PROTOCOL, quitonerror=0):
        if msg is None or msg.identity != "NAV-PVT" or not (msg.validDate and msg.validTime):
            continue
        if msg.fixType not in (2, 3, 4) or not msg.gnssFixOk:
            continue
        utc = dt.datetime(msg.year, msg.month, msg.day, msg.hour, msg.min, msg.second, tzinfo=dt.timezone.utc)
        t = int(utc.timestamp()) * 1_000_000_000 + int(msg.nano)
        fixes.append(contract.location_fix(
            t, t, float(msg.lat), float(msg.lon), msg.hMSL / 1000.0, msg.hAcc / 1000.0, msg.vAcc / 1000.0,
            gps_time_utc_ns=t, speed_mps=msg.gSpeed / 1000.0, course_deg=float(msg.headMot), fix_quality=1,
            satellites=int(msg.numSV), hdop=None))
    return fixes
