"""CAN source: every frame logged raw (`/can/frames`), plus the few requests the logger may send.

A reader thread (so the event loop never blocks) wakes every ``receive_interval_s`` and takes
every frame the interface buffered since (the kernel's socket buffer on socketcan, each frame
stamped on arrival), packed into the contract's 24-byte records; the asyncio task hands them to
the writer every ``batch_interval_s``. Waking on a cadence instead of for every frame spares the
CPU most of the thread wake-ups (1500 frames/s arrive in some 400 bursts). The reader also
answers what must be answered at once: ISO-TP flow control for multi-frame OBD-II responses and
J1939 CTS / end-of-message ACK for RTS sessions addressed to the logger; and it drives the OBD-II
poller (`ObdPoller.tick` after each wake-up's frames), so polling costs the event loop nothing.
Everything sent goes through `TxGuard`: an explicit allow-list of arbitration ids, and nothing at
all with ``listen_only``.
"""

from __future__ import annotations

import asyncio
import dataclasses
import threading

import can

from haulprofile import contract
from haulprofile.contract import j1939, obd
from ..clock import WALL_CLOCK_JUMP_NS
from ..config import CanSection
from ..diagnostics import worth_saying
from .base import Source
from .can_protocols import J1939Requester, ObdPoller

FRAME_RECORD = contract.record_struct(contract.CAN_FRAMES)
"""The contract's `/can/frames` record: ``pack(t_mono_ns, arbitration_id, flags, dlc, channel, 0, data)``."""

HW_TIMESTAMP_INTERFACES = {"socketcan"}
MAX_FRAMES_PER_WAKE = 10_000
"""Frames taken in one go before the reader looks at its stop flag again (a flooded bus)."""
RECEIVE_RETRY_S = 0.5
"""Wait after a receive error (interface down, bus-off) before the next try [s]."""


def allowed_tx_ids(section: CanSection) -> frozenset[int]:
    """Every arbitration id the configuration lets the logger transmit (empty if listen-only)."""
    if section.listen_only:
        return frozenset()
    ids: set[int] = set()
    if section.obd.enabled:
        if section.obd.addressing == "11bit":
            ids.add(obd.FUNCTIONAL_REQUEST_ID_11BIT)
            ids.update(r - 8 for r in obd.RESPONSE_IDS_11BIT)          # ISO-TP flow control
        else:
            ids.add(obd.FUNCTIONAL_REQUEST_ID_29BIT)
            ids.update(0x18DA00F1 | (ecu << 8) for ecu in range(256))  # flow control to each ECU
    if section.j1939.enabled:
        sa = section.j1939.source_address
        if section.j1939.request_pgns:
            ids.add(j1939.make_id(j1939.PGN_REQUEST, sa, 6, section.j1939.request_destination))
        if section.j1939.answer_rts:
            ids.update(j1939.make_id(j1939.PGN_TP_CM, sa, 7, dest) for dest in range(256))
    return frozenset(ids)


def transmit_warning(section: CanSection) -> str | None:
    """The one line said at start when the configuration lets the logger transmit (None if not)."""
    if not allowed_tx_ids(section):
        return None
    what = []
    if section.obd.enabled:
        what.append(f"OBD-II requests at {section.obd.rate_hz:g} Hz ({section.obd.addressing}) with ISO-TP flow control")
    if section.j1939.enabled and section.j1939.request_pgns:
        what.append(f"J1939 requests for PGN {', '.join(map(str, section.j1939.request_pgns))} every "
                    f"{section.j1939.request_interval_s:g} s from SA {section.j1939.source_address:#04x}")
    if section.j1939.enabled and section.j1939.answer_rts:
        what.append("J1939 CTS/ACK answers to RTS")
    return f"TRANSMITTING on {section.channel} (listen_only = false): {'; '.join(what)}"


def listening_section(section: CanSection, channel: str) -> CanSection:
    """The section of a further bus (``more_channels``): the same interface, listened to only."""
    return dataclasses.replace(section, channel=channel, listen_only=True, more_channels=[])


def _receive_hook(bus):
    """The backend's receive hook of a python-can bus without filters (the logger sets none), or
    None: `can.BusABC.recv` adds to it only a filter loop and a debug log, a quarter of the receive
    cost per frame on a saturated bus."""
    if isinstance(bus, can.BusABC) and bus.filters is None:
        return bus._recv_internal
    return None


class TxGuard:
    """The only way the logger transmits: checks the allow-list, logs what it sent."""

    def __init__(self, bus: can.BusABC, allowed: frozenset[int], record, say=None):
        self._bus = bus
        self.allowed = allowed
        self._record = record
        self._say = say or (lambda message: None)
        self.sent = 0
        self.blocked = 0
        self.errors = 0
        self.failing = 0
        """Failed sends in a row (bus-off, no ACK, interface down); 0 while sending works."""

    def send(self, arbitration_id: int, data: bytes, extended: bool) -> bool:
        if arbitration_id not in self.allowed:
            self.blocked += 1
            return False
        message = can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=extended)
        try:
            self._bus.send(message, timeout=0.05)
        except (can.CanError, OSError) as exc:
            self.errors += 1
            self.failing += 1
            if worth_saying(self.failing):
                self._say(f"can: send failed: {exc!r} ({self.failing} in a row); receiving goes on")
            return False
        if self.failing:
            self._say(f"can: sending works again after {self.failing} failed sends")
            self.failing = 0
        self.sent += 1
        self._record(arbitration_id, data, extended)
        return True


class CanSource(Source):
    """Raw frame logger with OBD-II poller and J1939 requester on one python-can bus."""

    name = "can"

    def __init__(self, queue, clock, section: CanSection, bus: can.BusABC | None = None, say=None,
                 drop_pgns: frozenset[int] = frozenset(), channel_index: int = 0):
        """``drop_pgns``: J1939 PGNs (PDU2) never logged (`..config.PrivacySection.drop_can_pgns`);
        ``channel_index``: the record's ``channel`` (0 the first bus; a further bus is source ``can1``…)."""
        super().__init__(queue, clock, say)
        self.channel_index = channel_index
        if channel_index:
            self.name = f"can{channel_index}"
        self.section = section
        self.drop_pgns = frozenset(drop_pgns)
        self.privacy_dropped = 0
        self.fd_truncated = 0
        """CAN FD frames longer than the record's 8 data bytes (flagged `CAN_FLAG_FD`)."""
        self.bus = bus if bus is not None else can.Bus(interface=section.interface, channel=section.channel,
                                                       bitrate=section.bitrate)
        self._hw_stamp = section.interface in HW_TIMESTAMP_INTERFACES
        self._lock = threading.Lock()
        self._buffer = bytearray()
        self._count = 0
        self._stop = threading.Event()
        self._offset_ns = clock.mono_offset_ns()
        self._thread: threading.Thread | None = None
        self.guard = TxGuard(self.bus, allowed_tx_ids(section), self._record_tx, self._say)
        if (warning := transmit_warning(section)) is not None:
            self.say(warning)
        sa = section.j1939.source_address
        self._tp_keys = {(j1939.PGN_TP_CM | sa), (j1939.PGN_TP_DT | sa)} if (
            section.j1939.enabled and section.j1939.answer_rts and not section.listen_only) else set()
        self.obd = ObdPoller(self, section.obd) if section.obd.enabled and not section.listen_only else None
        self.j1939 = (J1939Requester(self, section.j1939)
                      if section.j1939.enabled and section.j1939.request_pgns and not section.listen_only else None)
        if self.obd is not None:
            extended = section.obd.addressing == "29bit"
            self._obd_ids = (frozenset(obd.RESPONSE_ID_29BIT_BASE | e for e in range(256)) if extended
                             else frozenset(obd.RESPONSE_IDS_11BIT))
        else:
            self._obd_ids = frozenset()
        self._isotp: dict[int, list] = {}
        self._rts: dict[int, dict] = {}

    # --- reader thread -------------------------------------------------------------------------
    def _reader(self) -> None:
        clock = self.clock
        interval_s = clock.real_seconds(self.section.receive_interval_s)
        obd_due_ns: int | None = None
        failing = 0
        while not self._stop.is_set():
            timeout_s = 0.0
            if not interval_s:  # a frame at a time: block until one comes or the poller is due
                timeout_s = 0.2 if obd_due_ns is None else \
                    min(max(clock.real_seconds((obd_due_ns - clock.monotonic_ns()) * 1e-9), 0.0), 0.2)
            try:
                taken = self._take_buffered(timeout_s)
            except (can.CanError, OSError) as exc:  # interface down, bus-off: count, wait, retry
                self.stats.errors += 1
                failing += 1
                self.stats.state = "receive error"
                if failing in (1, 10, 100, 1000):
                    self._say(f"can: receive error {exc} ({failing} in a row); retrying every "
                              f"{RECEIVE_RETRY_S:g} s")
                self._stop.wait(RECEIVE_RETRY_S)
                continue
            if failing:
                self._say(f"can: receiving again after {failing} receive errors")
                failing = 0
                self.stats.state = "running"
            if self.obd is not None:
                obd_due_ns = self.obd.tick(clock.monotonic_ns())
            if interval_s > 0 and taken < MAX_FRAMES_PER_WAKE:
                self._stop.wait(interval_s)

    def _take_buffered(self, timeout_s: float) -> int:
        """Receive until the interface has nothing more (or ``timeout_s`` passed with nothing), at
        most `MAX_FRAMES_PER_WAKE` frames; they go to the shared buffer together, each with its own
        receive time. Returns how many were taken."""
        recv = self.bus.recv
        hook = _receive_hook(self.bus)
        pack = FRAME_RECORD.pack
        clock = self.clock
        scaled = clock.scale != 1.0
        hw_flag = contract.CAN_FLAG_HW_TIMESTAMP if self._hw_stamp else 0
        extended_flag = contract.CAN_FLAG_EXTENDED
        obd_ids, tp_keys = self._obd_ids, self._tp_keys
        drop_pgns = self.drop_pgns
        channel = self.channel_index
        records: list[bytes] = []
        taken = 0
        now_ns = clock.monotonic_ns()
        try:
            while taken < MAX_FRAMES_PER_WAKE and (
                    msg := hook(timeout_s)[0] if hook is not None else recv(timeout_s)) is not None:
                taken += 1
                arb = msg.arbitration_id
                extended = msg.is_extended_id
                if drop_pgns and extended and ((arb >> 8) & 0x3FFFF) in drop_pgns:
                    self.privacy_dropped += 1
                    continue
                flags = hw_flag | extended_flag if extended else hw_flag
                if msg.is_remote_frame:
                    flags |= contract.CAN_FLAG_REMOTE
                if msg.is_error_frame:
                    flags |= contract.CAN_FLAG_ERROR
                if msg.is_fd:
                    flags |= contract.CAN_FLAG_FD
                    self.fd_truncated += len(msg.data) > 8
                if scaled:
                    t_ns = clock.mono_ns_from_unix_s(msg.timestamp, 0)
                else:
                    t_ns = int(msg.timestamp * 1e9) - self._offset_ns
                    if abs(t_ns - now_ns) > WALL_CLOCK_JUMP_NS:
                        now_ns = clock.monotonic_ns()
                        if abs(t_ns - now_ns) > WALL_CLOCK_JUMP_NS:  # the wall clock was set
                            self._offset_ns = clock.mono_offset_ns()
                            t_ns = int(msg.timestamp * 1e9) - self._offset_ns
                data = msg.data
                records.append(pack(t_ns, arb, flags, msg.dlc, channel, 0, data))
                if arb in obd_ids:
                    self._commit(records)
                    self._on_obd_frame(arb, bytes(data), extended)
                elif tp_keys and extended and ((arb >> 8) & 0xFFFF) in tp_keys:
                    self._commit(records)
                    self._on_tp_frame(arb, bytes(data))
                if timeout_s:  # blocking receive: a frame at a time
                    break
        finally:
            self._commit(records)
        return taken

    def _commit(self, records: list[bytes]) -> None:
        """Move packed frames to the buffer `drain` hands to the writer (and empty ``records``)."""
        if records:
            with self._lock:
                self._buffer += b"".join(records)
                self._count += len(records)
            records.clear()

    def _record_tx(self, arbitration_id: int, data: bytes, extended: bool) -> None:
        flags = contract.CAN_FLAG_TX | (contract.CAN_FLAG_EXTENDED if extended else 0)
        record = FRAME_RECORD.pack(self.clock.monotonic_ns(), arbitration_id, flags, len(data), self.channel_index, 0,
                                   data)
        with self._lock:
            self._buffer += record
            self._count += 1

    def _on_obd_frame(self, arb: int, data: bytes, extended: bool) -> None:
        """ISO 15765-2 reassembly of a response; flow control to a first frame."""
        kind = data[0] >> 4
        if kind == 0:
            self._deliver_obd(arb, data[1:1 + (data[0] & 0x0F)])
        elif kind == 1:
            total = ((data[0] & 0x0F) << 8) | data[1]
            self._isotp[arb] = [total, bytearray(data[2:8])]
            fc_id = (0x18DA00F1 | ((arb & 0xFF) << 8)) if extended else arb - 8
            self.guard.send(fc_id, bytes([0x30, 0x00, 0x00]).ljust(8, bytes([obd.PAD_BYTE])), extended)
        elif kind == 2 and arb in self._isotp:
            total, payload = self._isotp[arb]
            payload += data[1:8]
            if len(payload) >= total:
                del self._isotp[arb]
                self._deliver_obd(arb, bytes(payload[:total]))

    def _deliver_obd(self, arb: int, payload: bytes) -> None:
        if self.obd is not None:
            self.obd.on_response(arb, payload)

    def _on_tp_frame(self, arb: int, data: bytes) -> None:
        """J1939-21 RTS/CTS as receiver: CTS for all packets, then end-of-message ACK."""
        _, pgn, sender, _ = j1939.parse_id(arb)
        sa = self.section.j1939.source_address
        if pgn == j1939.PGN_TP_CM and data[0] == j1939.TP_CM_RTS:
            packets = data[3]
            self._rts[sender] = {"size": data[1] | (data[2] << 8), "packets": packets, "received": 0,
                                 "pgn": bytes(data[5:8])}
            cts = bytes([j1939.TP_CM_CTS, packets, 1, 0xFF, 0xFF]) + bytes(data[5:8])
            self.guard.send(j1939.make_id(j1939.PGN_TP_CM, sa, 7, sender), cts, True)
        elif pgn == j1939.PGN_TP_CM and data[0] == j1939.TP_CM_ABORT:
            self._rts.pop(sender, None)
        elif pgn == j1939.PGN_TP_DT and sender in self._rts:
            session = self._rts[sender]
            session["received"] += 1
            if session["received"] >= session["packets"]:
                del self._rts[sender]
                ack = bytes([j1939.TP_CM_EOM_ACK, session["size"] & 0xFF, session["size"] >> 8,
                             session["packets"], 0xFF]) + session["pgn"]
                self.guard.send(j1939.make_id(j1939.PGN_TP_CM, sa, 7, sender), ack, True)

    # --- asyncio side --------------------------------------------------------------------------
    def drain(self) -> None:
        """Hand the frames received so far to the writer as one packed message."""
        with self._lock:
            payload, count = bytes(self._buffer), self._count
            self._buffer.clear()
            self._count = 0
        if self.clock.scale == 1.0:
            self._offset_ns = self.clock.mono_offset_ns()
        if count:
            first_t = contract.first_time_ns(payload)
            self.emit(contract.CAN_FRAMES, payload, first_t, records=count)

    def update_extra(self) -> None:
        extra = {"tx_sent": self.guard.sent, "tx_blocked": self.guard.blocked, "tx_errors": self.guard.errors,
                 "listen_only": self.section.listen_only}
        if self.drop_pgns:
            extra["privacy_dropped"] = self.privacy_dropped
        if self.fd_truncated:
            extra["fd_truncated"] = self.fd_truncated
        if self.obd is not None:
            extra.update(self.obd.stats())
        if self.j1939 is not None:
            extra.update(self.j1939.stats())
        self.stats.extra = extra

    async def run(self) -> None:
        self._thread = threading.Thread(target=self._reader, name=f"{self.name}-reader", daemon=True)
        self._thread.start()
        tasks = [asyncio.create_task(self.j1939.run())] if self.j1939 is not None else []
        self.stats.state = "running"
        try:
            while True:
                await self.clock.sleep(self.section.batch_interval_s)
                if not self._thread.is_alive():
                    self.stats.state = "reader stopped"
                    raise RuntimeError("CAN reader thread stopped")
                self.drain()
                self.update_extra()
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    async def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            await asyncio.get_running_loop().run_in_executor(None, self._thread.join, 2.0)
        self.drain()
        self.update_extra()
        self.bus.shutdown()
