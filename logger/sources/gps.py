"""GPS source: NMEA 0183 from a u-blox receiver on a serial port (pyserial + pynmea2).

The port is read without blocking (``loop.add_reader`` on its file descriptor). Every line is
kept raw in ``/gps/nmea`` (checksum-valid or not); the sentences of one epoch become one
``/gps/fix`` (`haulprofile.contract.nmea`). Bad checksums, proprietary sentences, binary UBX
bytes and truncated lines are counted and skipped, never fatal.

With privacy zones or coarsening (`..privacy.Privacy`) the raw lines of an epoch are held until
the epoch is judged: inside a zone its fix, its NMEA (every line, checksum-valid or not) and its
GPS time are dropped and ``/privacy/zone`` says where such a stretch begins and ends; outside,
the fix is coarsened and the NMEA kept only if nothing is coarsened. An epoch is judged by its fix
and by every position its lines carry (GGA, RMC, GLL, GNS; any fix quality, bad checksums too),
so an epoch without a complete fix cannot carry a position out of a zone; a position sentence
that cannot be read is never written. Before the first position, and while epochs without one
follow a position inside a zone, epochs count as inside.
"""

from __future__ import annotations

import asyncio
import struct

from haulprofile import contract
from haulprofile.contract.nmea import EpochFixes
from .base import Source

MAX_LINE_BYTES = 512
REOPEN_S = 1.0
"""How often a lost serial port (receiver unplugged, tty gone) is tried again [s]."""


def ubx_message(msg_class: int, msg_id: int, payload: bytes) -> bytes:
    """A UBX frame with its 8-bit Fletcher checksum (u-blox 7 receiver description, section 31.4)."""
    body = bytes([msg_class, msg_id]) + struct.pack("<H", len(payload)) + payload
    ck_a = ck_b = 0
    for byte in body:
        ck_a = (ck_a + byte) & 0xFF
        ck_b = (ck_b + ck_a) & 0xFF
    return b"\xb5\x62" + body + bytes([ck_a, ck_b])


NMEA_GST = (0xF0, 0x07)
"""UBX class and id of NMEA GxGST, the fix's error estimates (the vertical accuracy the gradient
weighs GPS altitude by): a u-blox 7 sends TXT, RMC, VTG, GGA, GSA, GSV and GLL by default, not GST."""


def ubx_cfg_msg(msg_class: int, msg_id: int, rate: int) -> bytes:
    """UBX-CFG-MSG for the port it arrives on: message ``msg_class``/``msg_id`` once every ``rate``
    navigation solutions (0: off)."""
    return ubx_message(0x06, 0x01, bytes([msg_class, msg_id, rate]))


def ubx_cfg_rate(rate_hz: float) -> bytes:
    """UBX-CFG-RATE: measurement period [ms], one navigation solution per measurement, GPS time."""
    return ubx_message(0x06, 0x08, struct.pack("<HHH", int(round(1000.0 / rate_hz)), 1, 1))


class GpsSource(Source):
    """Reads NMEA lines from a serial port path; one fix per receiver epoch."""

    name = "gps"

    def __init__(self, queue, clock, port: str, baudrate: int = 9600, configure_rate_hz: float | None = None,
                 say=None, privacy=None, request_accuracy: bool = False):
        super().__init__(queue, clock, say)
        self.privacy = privacy if privacy is not None and privacy.active else None
        self._pending: list[tuple[str, int]] = []
        """Lines of the epoch being read, held until it is judged (privacy only)."""
        self._inside: bool | None = None
        """Last judgement: in a zone (True), outside (False), no fix yet (None)."""
        self._carry = 0
        """Held lines that begin the next epoch (1 while a sentence is being handled)."""
        self.port_path = port
        self.baudrate = baudrate
        self.configure_rate_hz = configure_rate_hz
        self.request_accuracy = request_accuracy
        """Ask the receiver for GST at every opening (a replugged receiver has forgotten it)."""
        self.serial = None
        self._buffer = bytearray()
        self._raw: list[str] = []
        self._raw_t: list[int] = []
        self.last_gps_time = None
        self._epoch_interval_ns: int | None = None
        """Shortest UTC step seen between written fixes: the receiver's epoch interval."""
        self._reading: int | None = None
        self._last_try_ns = 0
        for key in ("lines", "fixes", "bad_checksum", "parse_errors", "skipped", "zone_epochs"):
            self.stats.extra[key] = 0
        self._nmea = EpochFixes(self._on_epoch, self.stats.extra, lambda: self.clock.mono_offset_ns(),
                                fixless=True)

    def open(self) -> None:
        import serial
        self.serial = serial.Serial(self.port_path, self.baudrate, timeout=0)
        if self.configure_rate_hz:
            self.serial.write(ubx_cfg_rate(self.configure_rate_hz))
        if self.request_accuracy:
            self.serial.write(ubx_cfg_msg(*NMEA_GST, 1))

    def feed(self, data: bytes, t_mono_ns: int) -> None:
        """Split received bytes into lines and handle each complete one."""
        self._buffer += data
        while True:
            end = self._buffer.find(b"\n")
            if end < 0:
                if len(self._buffer) > MAX_LINE_BYTES:
                    self._buffer.clear()
                    self.stats.extra["skipped"] += 1
                return
            line = bytes(self._buffer[:end]).rstrip(b"\r")
            del self._buffer[:end + 1]
            self.handle_line(line, t_mono_ns)

    def handle_line(self, line: bytes, t_mono_ns: int) -> None:
        start = line.find(b"$")
        if start < 0:
            if line.strip():
                self.stats.extra["skipped"] += 1
            return
        text = line[start:].decode("ascii", errors="replace")
        self.stats.extra["lines"] += 1
        if self.privacy is None:
            self._raw.append(text)
            self._raw_t.append(t_mono_ns)
        else:
            self._pending.append((text, t_mono_ns))
        self._carry = 1
        try:
            self._nmea.sentence(text, t_mono_ns)
        finally:
            self._carry = 0

    def flush_epoch(self) -> None:
        self._nmea.flush()

    def _on_epoch(self, epoch, fix: dict | None) -> None:
        """A closed epoch (``fix`` None: it had none; ``epoch`` None: there was none): with privacy its held lines, except the one
        that begins the next epoch, are judged with it; the fix that may be written is written."""
        t_mono_ns = epoch.t_mono_ns if epoch is not None else None
        if self.privacy is not None:
            held = self._pending[:len(self._pending) - self._carry]
            del self._pending[:len(held)]
            fix = self._judge(fix, held, t_mono_ns)
        if fix is None:
            return
        self.emit_json(contract.GPS_FIX, fix, t_mono_ns)
        self.stats.extra["fixes"] += 1
        if fix["gps_time_utc_ns"] is not None:
            if self.last_gps_time is not None and fix["gps_time_utc_ns"] > self.last_gps_time[1]:
                step = fix["gps_time_utc_ns"] - self.last_gps_time[1]
                self._epoch_interval_ns = min(step, self._epoch_interval_ns or step)
            self.last_gps_time = (t_mono_ns, fix["gps_time_utc_ns"])

    def _judge(self, fix: dict | None, held: list[tuple[str, int]], t_mono_ns: int | None) -> dict | None:
        """Privacy: the fix to write (None inside a zone); the held lines go on or are dropped."""
        was = self._inside
        by_lines, unreadable = self.privacy.lines_inside(text for text, _ in held)
        located = fix is not None or by_lines is not None
        inside = (bool(by_lines) or (fix is not None and self.privacy.inside(fix["latitude"], fix["longitude"]))
                  if located else (was is not False))
        if located and inside != bool(was) and t_mono_ns is not None:
            self.emit_json(contract.PRIVACY_ZONE, {"t_mono_ns": t_mono_ns, "event": "entered" if inside else "left",
                                                   "source": "logger"}, t_mono_ns)
        if located:
            self._inside = inside
        if inside:
            self.stats.extra["zone_epochs"] += t_mono_ns is not None
            self.last_gps_time = None
            return None
        self.stats.extra["unreadable_positions"] = self.stats.extra.get("unreadable_positions", 0) + len(unreadable)
        if self.privacy.keep_nmea:
            for index, (text, t) in enumerate(held):
                if index not in unreadable:
                    self._raw.append(text)
                    self._raw_t.append(t)
        return self.privacy.coarsen_fix(fix) if fix is not None else None

    def flush_raw(self) -> None:
        if self._raw:
            record = {"t_mono_ns": self._raw_t[0], "sentences": self._raw, "t_mono_ns_each": self._raw_t}
            self.emit_json(contract.GPS_NMEA, record, self._raw_t[0])
            self._raw, self._raw_t = [], []

    def gps_time_now_ns(self) -> int | None:
        """GPS UTC [ns] extrapolated to now from the last fix, if that fix is under 2 s old. With
        privacy zones only up to the receiver's next epoch: that epoch may be waiting to be judged
        (an epoch is judged when the next begins, later on a loaded machine) and be inside a zone,
        whose times the file must not hold."""
        if self.last_gps_time is None:
            return None
        t_fix, utc = self.last_gps_time
        age = self.clock.monotonic_ns() - t_fix
        limit = 2_000_000_000
        if self.privacy is not None:
            limit = min(limit, self._epoch_interval_ns or 0)
        return utc + age if age < limit else None

    def _on_readable(self) -> None:
        try:
            data = self.serial.read(4096)
        except OSError as exc:  # serial.SerialException too: receiver unplugged
            self.stats.errors += 1
            self.say(f"serial read error on {self.port_path}: {exc}; reopening every {REOPEN_S:g} s")
            self._detach()
            return
        if data:
            self.feed(data, self.clock.monotonic_ns())

    def _detach(self) -> None:
        if self.serial is not None and self._reading:
            asyncio.get_running_loop().remove_reader(self._reading)
        self._reading = None
        if self.serial is not None:
            self.serial.close()
        self.stats.state = "port lost"

    def _attach(self) -> None:
        if self.serial is None or not self.serial.is_open:
            self.open()
        self._reading = self.serial.fileno()
        asyncio.get_running_loop().add_reader(self._reading, self._on_readable)
        self.stats.state = "running"

    async def run(self) -> None:
        self._attach()
        try:
            while True:
                await self.clock.sleep(1.0)
                self.flush_raw()
                if self._reading is None and self.clock.monotonic_ns() - self._last_try_ns > REOPEN_S * 1e9:
                    self._last_try_ns = self.clock.monotonic_ns()
                    try:
                        self._attach()
                        self.say(f"{self.port_path} open again")
                    except OSError:
                        pass
        finally:
            if self._reading is not None:
                asyncio.get_running_loop().remove_reader(self._reading)
                self._reading = None

    async def close(self) -> None:
        if self.serial is not None and self.serial.is_open:
            try:
                data = self.serial.read(65536)
            except OSError:
                data = b""
            if data:
                self.feed(data, self.clock.monotonic_ns())
        if self._buffer.strip():
            self.handle_line(bytes(self._buffer).rstrip(b"\r"), self.clock.monotonic_ns())
            self._buffer.clear()
        self.flush_epoch()
        self.flush_raw()
        if self.serial is not None:
            self.serial.close()
