"""The configuration's ``[privacy]`` as the daemon applies it, before anything reaches the disk.

One `Privacy` per daemon: the GPS source asks it whether an epoch lies in a zone and hands it
each fix to coarsen; the writer takes every MCAP ``log_time`` through `log_time`; the daemon
takes ``/time/sync`` through it; the CAN source drops the PGNs in `can_drop_pgns`.
"""

from __future__ import annotations

import math
import time

from haulprofile.contract.privacy import CoarseClock, in_any, snap_position, zones_from_tables

from .config import PrivacySection


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
