"""The configuration's ``[privacy]`` as the daemon applies it, before anything reaches the disk.

One `Privacy` per daemon: the GPS source asks it whether an epoch lies in a zone and hands it
each fix to coarsen; the writer takes every MCAP ``log_time`` through `log_time`; the daemon
takes ``/time/sync`` through it; the CAN source drops the PGNs in `can_drop_pgns`.
"""

from __future__ import annotations

import math
import time

from haulprofile.contract.nmea import nmea_checksum_ok
from haulprofile.contract.privacy import CoarseClock, in_any, snap_position, zones_from_tables

from .config import PrivacySection

POSITION_TYPES = ("GGA", "RMC", "GLL", "GNS")
"""NMEA sentences that carry a position (talker GP, GN, GL, GA, BD...)."""
UNREADABLE = object()


def sentence_position(text: str):
    """(latitude, longitude) [deg] of a position sentence, read even with a bad checksum or a
    fix quality of 0; None for a sentence without a position (or an empty one); `UNREADABLE`
    for a position sentence whose fields cannot be read."""
    import pynmea2

    body = text.strip()
    if len(body) < 6 or body[3:6] not in POSITION_TYPES or body.startswith("$P"):
        return None
    try:
        msg = pynmea2.parse(body, check=False)
        if not (getattr(msg, "lat", "") and getattr(msg, "lon", "")):
            return None
        latitude, longitude = float(msg.latitude), float(msg.longitude)
    except (pynmea2.ParseError, ValueError, TypeError, AttributeError, IndexError):
        return UNREADABLE
    if not (math.isfinite(latitude) and math.isfinite(longitude) and abs(latitude) <= 90 and abs(longitude) <= 180):
        return UNREADABLE
    return latitude, longitude


class Privacy:
    def __init__(self, section: PrivacySection):
        self.section = section
        self.zones = zones_from_tables(section.zones, "privacy.zones")
        self.grid_m = section.position_grid_m
        self.resolution_ns = int(round(section.time_resolution_s * 1e9))
        self.active = section.active
        self.wall_clock = CoarseClock(self.resolution_ns) if self.resolution_ns else None
        self.gps_clock = CoarseClock(self.resolution_ns) if self.resolution_ns else None
        self.keep_nmea = not (self.grid_m > 0 or self.resolution_ns)
        """Raw NMEA carries full-precision positions and times: kept only without coarsening."""
        self.can_drop_pgns = frozenset(section.drop_can_pgns) if self.active else frozenset()

    def log_time(self, t_realtime_ns: int, t_mono_ns: int) -> int:
        """MCAP ``log_time`` (and any wall-clock field) as written."""
        if self.wall_clock is None:
            return t_realtime_ns
        return self.wall_clock(t_realtime_ns, t_mono_ns)

    def file_time(self) -> time.struct_time:
        """UTC for a file name, rounded down to the resolution."""
        now = time.time()
        if self.resolution_ns:
            step = self.resolution_ns * 1e-9
            now = math.floor(now / step) * step
        return time.gmtime(now)

    def inside(self, latitude: float, longitude: float) -> bool:
        return bool(self.zones) and in_any(self.zones, latitude, longitude)

    def lines_inside(self, lines) -> tuple[bool | None, set[int]]:
        """Judge raw NMEA ``lines`` by every position they carry, whatever the sentence type
        (`POSITION_TYPES`), fix quality or checksum: (True if one lies in a zone, False if all lie
        outside, None if none has a position; the indexes of position sentences that cannot be
        trusted, unreadable or with a bad checksum, which are never written)."""
        judged, unreadable = None, set()
        for index, text in enumerate(lines):
            position = sentence_position(text)
            if position is None:
                continue
            if position is UNREADABLE or not nmea_checksum_ok(text.strip()):
                unreadable.add(index)
            if position is not UNREADABLE:
                judged = self.inside(*position) or bool(judged)
        return judged, unreadable

    def coarsen_fix(self, fix: dict) -> dict:
        """A ``/gps/fix`` record outside every zone, as written: position on the grid (its
        covariance grown by the grid's uniform error, grid²/12 per axis), times coarsened."""
        if self.grid_m > 0:
            fix["latitude"], fix["longitude"] = snap_position(fix["latitude"], fix["longitude"], self.grid_m)
            extra = self.grid_m ** 2 / 12.0
            cov = list(fix["position_covariance"])
            cov[0] += extra
            cov[4] += extra
            fix["position_covariance"] = cov
            if fix.get("h_acc_m") is not None:
                fix["h_acc_m"] = math.sqrt(fix["h_acc_m"] ** 2 + 2 * extra)
        if self.resolution_ns:
            t_mono = fix["t_mono_ns"]
            if fix.get("gps_time_utc_ns") is not None:
                fix["gps_time_utc_ns"] = self.gps_clock(fix["gps_time_utc_ns"], t_mono)
                wall = fix["gps_time_utc_ns"]
            else:
                stamp = fix["timestamp"]
                wall = self.wall_clock(stamp["sec"] * 1_000_000_000 + stamp["nsec"], t_mono)
            fix["timestamp"] = {"sec": wall // 1_000_000_000, "nsec": wall % 1_000_000_000}
        return fix
