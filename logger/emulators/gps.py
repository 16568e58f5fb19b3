"""A u-blox-7-like GPS writing NMEA 0183 (RMC, VTG, GGA, GSA) into a pseudo-terminal, and GST once
asked for it.

The serial source opens ``emulator.port`` (the pty's slave path) exactly as it opens
``/dev/ttyACM0`` on the truck. Every sentence written is kept in ``sent``; bytes the logger
writes to the receiver (UBX configuration) are collected in ``received``. As a u-blox 7, it sends
no GST (the fix's error estimates) until a UBX-CFG-MSG turns it on, and forgets that when it is
unplugged (its configuration is not saved).
"""

from __future__ import annotations

import datetime as dt
import math
import os
import threading
import tty

from ..clock import Clock
from .signals import TimeSeries

KNOT_MPS = 1852.0 / 3600.0


def with_checksum(body: str) -> str:
    """``$body*hh`` with the NMEA XOR checksum."""
    checksum = 0
    for char in body:
        checksum ^= ord(char)
    return f"${body}*{checksum:02X}"


def _lat(deg: float) -> tuple[str, str]:
    a = abs(deg)
    d = int(a)
    return f"{d:02d}{(a - d) * 60:08.5f}", "N" if deg >= 0 else "S"


def _lon(deg: float) -> tuple[str, str]:
    a = abs(deg)
    d = int(a)
    return f"{d:03d}{(a - d) * 60:08.5f}", "E" if deg >= 0 else "W"


CFG_MSG_GST = bytes([0xB5, 0x62, 0x06, 0x01, 0x03, 0x00, 0xF0, 0x07])
"""A UBX-CFG-MSG frame for NMEA GST up to its rate byte (`..sources.gps.ubx_cfg_msg`)."""


def gst_rate(received: bytes) -> int:
    """The GST rate the last UBX-CFG-MSG for it in ``received`` set (0: none asked for, or off)."""
    at = received.rfind(CFG_MSG_GST)
    return received[at + len(CFG_MSG_GST)] if 0 <= at and at + len(CFG_MSG_GST) < len(received) else 0


def epoch_sentences(utc: dt.datetime, values: dict, gst: bool = True) -> list[str]:
    """The NMEA sentences of one epoch from ``latitude_deg, longitude_deg, altitude_m, speed_mps,
    course_deg, h_acc_m, v_acc_m`` [deg, m, m/s]; GST only if ``gst``."""
    hms = utc.strftime("%H%M%S") + f".{utc.microsecond // 10000:02d}"
    date = utc.strftime("%d%m%y")
    if not values.get("fix_quality", 1) or not math.isfinite(values.get("latitude_deg", math.nan)):
        return [with_checksum(f"GPRMC,{hms},V,,,,,,,{date},,,N"), with_checksum("GPVTG,,T,,M,,N,,K,N"),
                with_checksum(f"GPGGA,{hms},,,,,0,00,99.99,,,,,,"),
                with_checksum("GPGSA,A,1,,,,,,,,,,,,,99.99,99.99,99.99")] + (
                    [with_checksum(f"GPGST,{hms},,,,,,,")] if gst else [])
    lat, ns = _lat(values["latitude_deg"])
    lon, ew = _lon(values["longitude_deg"])
    knots = values.get("speed_mps", 0.0) / KNOT_MPS
    course = values.get("course_deg", 0.0) % 360.0
    h_acc, v_acc = values.get("h_acc_m", 2.5), values.get("v_acc_m", 4.0)
    hdop = max(h_acc / 2.5, 0.5)
    axis_err = h_acc / math.sqrt(2.0)
    return [
        with_checksum(f"GPRMC,{hms},A,{lat},{ns},{lon},{ew},{knots:.3f},{course:.2f},{date},,,A"),
        with_checksum(f"GPVTG,{course:.2f},T,,M,{knots:.3f},N,{knots * 1.852:.3f},K,A"),
        with_checksum(f"GPGGA,{hms},{lat},{ns},{lon},{ew},1,09,{hdop:.2f},{values['altitude_m']:.1f},M,47.0,M,,"),
        with_checksum(f"GPGSA,A,3,02,05,07,09,13,16,20,23,30,,,,{hdop * 1.6:.2f},{hdop:.2f},{hdop * 1.3:.2f}"),
    ] + ([with_checksum(f"GPGST,{hms},{h_acc:.2f},,,,{axis_err:.2f},{axis_err:.2f},{v_acc:.2f}")] if gst else [])


class GpsEmulator:
    """Writes one epoch every ``1 / rate_hz`` emulated seconds into a pty."""

    def __init__(self, signals: TimeSeries, clock: Clock, t0_ns: int, rate_hz: float = 10.0,
                 start_utc: dt.datetime | None = None, link: str | os.PathLike | None = None):
        """``link``: a stable path (as udev's ``/dev/haulprofile-gps``) that points at the pty; the
        logger opens it, and `replug` points it at a new pty."""
        self.signals = signals
        self.clock = clock
        self.t0_ns = t0_ns
        self.rate_hz = rate_hz
        self.start_utc = start_utc or dt.datetime(2024, 5, 14, 8, 0, 0)
        self.link = None if link is None else os.fspath(link)
        self._fd_lock = threading.Lock()
        self.unplugged = False
        self._open_pty()
        self.sent: list[str] = []
        self.received = bytearray()
        self._configured_from = 0
        """Where in ``received`` the receiver now plugged in began to listen."""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _open_pty(self) -> None:
        self.master_fd, self.slave_fd = os.openpty()
        tty.setraw(self.slave_fd)
        self.tty = os.ttyname(self.slave_fd)
        if self.link is None:
            self.port = self.tty
            return
        temporary = f"{self.link}.new"
        if os.path.lexists(temporary):
            os.remove(temporary)
        os.symlink(self.tty, temporary)
        os.replace(temporary, self.link)
        self.port = self.link

    def unplug(self) -> None:
        """The receiver is gone: the pty is hung up (the logger's reads fail); epochs are not sent."""
        with self._fd_lock:
            self.unplugged = True
            for fd in (self.master_fd, self.slave_fd):
                try:
                    os.close(fd)
                except OSError:
                    pass

    def replug(self) -> None:
        """The receiver is back on a new tty; ``link`` points at it."""
        with self._fd_lock:
            self._open_pty()
            self._configured_from = len(self.received)
            self.unplugged = False

    def start(self) -> "GpsEmulator":
        self._thread = threading.Thread(target=self._run, name="gps-emulator", daemon=True)
        self._thread.start()
        return self

    def values(self, t_s: float) -> dict:
        names = ("latitude_deg", "longitude_deg", "altitude_m", "speed_mps", "course_deg", "h_acc_m", "v_acc_m",
                 "fix_quality")
        values = {"latitude_deg": 48.137, "longitude_deg": 11.575, "altitude_m": 520.0}
        values.update(self.signals.values(names, t_s))
        return values

    def _run(self) -> None:
        period_ns = int(1e9 / self.rate_hz)
        k = 1
        while not self._stop.is_set():
            due_ns = self.t0_ns + k * period_ns
            wait_ns = due_ns - self.clock.monotonic_ns()
            if wait_ns > 0:
                self.clock.thread_sleep(min(wait_ns * 1e-9, 0.1))
                continue
            t_s = k / self.rate_hz
            utc = self.start_utc + dt.timedelta(seconds=round(t_s, 2))
            sentences = epoch_sentences(utc, self.values(t_s), gst_rate(bytes(self.received[self._configured_from:])) > 0)
            k += 1
            with self._fd_lock:
                if self.unplugged:
                    continue
                try:
                    os.write(self.master_fd, "".join(s + "\r\n" for s in sentences).encode("ascii"))
                except OSError:
                    return
                self.sent.extend(sentences)
                self._drain_input()

    def _drain_input(self) -> None:
        import select
        while select.select([self.master_fd], [], [], 0)[0]:
            try:
                data = os.read(self.master_fd, 4096)
            except OSError:
                return
            if not data:
                return
            self.received += data

    def write_raw(self, data: bytes) -> None:
        """Write arbitrary bytes (a recorded receiver stream, line noise) into the pty."""
        with self._fd_lock:
            os.write(self.master_fd, data)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)

    def close(self) -> None:
        self.stop()
        if not self.unplugged:
            self.unplug()
        if self.link is not None and os.path.islink(self.link):
            os.remove(self.link)
