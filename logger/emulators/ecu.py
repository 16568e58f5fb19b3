"""An engine ECU on a python-can bus: J1939 broadcast (with BAM), PGN requests, RTS/CTS, OBD-II.

Runs in its own thread on its own bus object; every frame it transmits is kept in ``sent`` as
``(arbitration_id, is_extended, data)`` so tests compare the log with what was really on the bus.
"""

from __future__ import annotations

import heapq
import threading

import can

from haulprofile.contract import j1939, obd
from ..clock import Clock
from .signals import TimeSeries

BROADCAST_PERIODS_S = {
    j1939.PGN_EEC1: 0.02,
    j1939.PGN_EEC2: 0.05,
    j1939.PGN_EEC3: 0.25,
    j1939.PGN_CCVS1: 0.1,
    j1939.PGN_ETC2: 0.1,
    j1939.PGN_EBC1: 0.1,
    j1939.PGN_LFE: 0.1,
    j1939.PGN_CVW: 1.0,
}
"""Broadcast periods [s] (typical of heavy trucks; EEC1 is engine-speed dependent, 10-20 ms)."""

BAM_PERIOD_S = 5.0
BAM_PACKET_GAP_S = 0.05
"""J1939-21: 50 to 200 ms between the packets of a BAM session."""

PRIORITY = {j1939.PGN_EEC1: 3, j1939.PGN_EEC2: 3, j1939.PGN_ETC2: 3, j1939.PGN_EBC1: 6}

OBD_SIGNAL = {pid: p.name for pid, p in obd.PIDS.items()}


class EcuEmulator:
    """Engine ECU at J1939 source address ``source_address`` and OBD-II ECU #1 (0x7E8 / 0x18DAF1xx)."""

    def __init__(self, bus: can.BusABC, signals: TimeSeries, clock: Clock, source_address: int = 0x00,
                 broadcast: bool = True, answer_obd: bool = True, bam_period_s: float | None = BAM_PERIOD_S,
                 periods_s: dict[int, float] | None = None):
        self.bus = bus
        self.signals = signals
        self.clock = clock
        self.sa = source_address
        self.answer_obd = answer_obd
        self.periods_s = dict(BROADCAST_PERIODS_S if periods_s is None else periods_s) if broadcast else {}
        self.bam_period_s = bam_period_s if broadcast else None
        self.sent: list[tuple[int, bool, bytes]] = []
        self.received_requests = 0
        self.silent = False
        """True: the ECU sends and answers nothing (powered down, disconnected); its schedule runs on."""
        self._events: list[tuple[int, int, str, object]] = []
        self._seq = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0_ns = 0
        self._pending_isotp: dict[int, list[bytes]] = {}
        self._pending_rts: dict[int, list[bytes]] = {}
        self._names: dict[int, list[str]] = {}
        """SPN names per PGN, looked up once: the broadcast encodes a frame every few ms."""

    # --- scheduling ----------------------------------------------------------------------------
    def _schedule(self, t_ns: int, kind: str, arg) -> None:
        self._seq += 1
        heapq.heappush(self._events, (t_ns, self._seq, kind, arg))

    def t_s(self) -> float:
        return (self.clock.monotonic_ns() - self._t0_ns) * 1e-9

    def start(self, t0_ns: int | None = None) -> "EcuEmulator":
        """Start broadcasting; signal time 0 is ``t0_ns`` (monotonic, default now)."""
        self._t0_ns = self.clock.monotonic_ns() if t0_ns is None else t0_ns
        now = self.clock.monotonic_ns()
        for pgn, period in self.periods_s.items():
            self._schedule(now + int(period * 1e9), "broadcast", pgn)
        if self.bam_period_s:
            self._schedule(now + int(self.bam_period_s * 1e9), "bam", j1939.PGN_EC1)
        self._thread = threading.Thread(target=self._run, name="ecu-emulator", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)

    def _send(self, arbitration_id: int, data: bytes, extended: bool) -> None:
        if self.silent:
            return
        self.bus.send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=extended))
        self.sent.append((arbitration_id, extended, bytes(data)))

    def _run(self) -> None:
        while not self._stop.is_set():
            now = self.clock.monotonic_ns()
            while self._events and self._events[0][0] <= now:
                t_ns, _, kind, arg = heapq.heappop(self._events)
                self._fire(t_ns, kind, arg)
            wait_ns = (self._events[0][0] - now) if self._events else 100_000_000
            msg = self.bus.recv(timeout=min(max(wait_ns, 0) * 1e-9 / self.clock.scale, 0.1))
            if msg is not None and not self.silent:
                self._on_frame(msg)

    def _fire(self, t_ns: int, kind: str, arg) -> None:
        if kind == "broadcast":
            pgn = arg
            self._send(j1939.make_id(pgn, self.sa, PRIORITY.get(pgn, 6)), self.pgn_data(pgn), True)
            self._schedule(t_ns + int(self.periods_s[pgn] * 1e9), "broadcast", pgn)
        elif kind == "bam":
            self._start_bam(arg, t_ns)
            self._schedule(t_ns + int(self.bam_period_s * 1e9), "bam", arg)
        elif kind == "frame":
            self._send(*arg)

    # --- J1939 ---------------------------------------------------------------------------------
    def pgn_data(self, pgn: int) -> bytes:
        names = self._names.get(pgn)
        if names is None:
            names = self._names[pgn] = [s.name for s in j1939.spns_of(pgn)]
        return j1939.encode_pgn(pgn, self.signals.values(names, self.t_s()))

    def _start_bam(self, pgn: int, t_ns: int) -> None:
        frames = j1939.bam_frames(pgn, self.pgn_data(pgn))
        self._send(j1939.make_id(j1939.PGN_TP_CM, self.sa, 7), frames[0], True)
        for i, dt in enumerate(frames[1:], start=1):
            self._schedule(t_ns + int(i * BAM_PACKET_GAP_S * 1e9), "frame",
                           (j1939.make_id(j1939.PGN_TP_DT, self.sa, 7), dt, True))

    def _on_request(self, requester: int, destination: int, pgn: int) -> None:
        self.received_requests += 1
        data = self.pgn_data(pgn)
        now = self.clock.monotonic_ns()
        if len(data) <= 8:
            self._send(j1939.make_id(pgn, self.sa, 6, requester), data, True)
        elif destination == j1939.GLOBAL_ADDRESS:
            self._start_bam(pgn, now)
        else:
            packets = (len(data) + 6) // 7
            rts = bytes([j1939.TP_CM_RTS, len(data) & 0xFF, len(data) >> 8, packets, 0xFF]) + pgn.to_bytes(3, "little")
            self._pending_rts[requester] = [
                bytes([i + 1]) + data[7 * i:7 * i + 7].ljust(7, b"\xff") for i in range(packets)]
            self._send(j1939.make_id(j1939.PGN_TP_CM, self.sa, 7, requester), rts, True)

    def _on_tp_cm(self, sender: int, data: bytes) -> None:
        if data[0] == j1939.TP_CM_CTS and sender in self._pending_rts:
            packets = self._pending_rts[sender]
            count, first = data[1], data[2]
            for dt in packets[first - 1:first - 1 + count]:
                self._send(j1939.make_id(j1939.PGN_TP_DT, self.sa, 7, sender), dt, True)
        elif data[0] in (j1939.TP_CM_EOM_ACK, j1939.TP_CM_ABORT):
            self._pending_rts.pop(sender, None)

    # --- OBD-II --------------------------------------------------------------------------------
    def _obd_payload(self, pids: bytes) -> bytes | None:
        out = bytearray([obd.SERVICE_CURRENT_DATA + obd.POSITIVE_RESPONSE_OFFSET])
        t_s = self.t_s()
        for pid in pids:
            if pid not in obd.PIDS or not self.signals.has(OBD_SIGNAL[pid]):
                continue
            out += bytes([pid, *obd.PIDS[pid].encode(self.signals.value(OBD_SIGNAL[pid], t_s))])
        return bytes(out) if len(out) > 1 else None

    def _on_obd_request(self, data: bytes, extended: bool) -> None:
        if data[0] >> 4 != 0 or len(data) < 3 or data[1] != obd.SERVICE_CURRENT_DATA:
            return
        self.received_requests += 1
        payload = self._obd_payload(bytes(data[2:1 + (data[0] & 0x0F)]))
        if payload is None:
            return
        response_id = (obd.RESPONSE_ID_29BIT_BASE | self.sa) if extended else 0x7E8
        pad = bytes([obd.PAD_BYTE])
        if len(payload) <= 7:
            self._send(response_id, bytes([len(payload)]) + payload.ljust(7, pad), extended)
            return
        first = bytes([0x10 | (len(payload) >> 8), len(payload) & 0xFF]) + payload[:6]
        rest = payload[6:]
        self._pending_isotp[response_id] = [
            bytes([0x20 | ((i + 1) & 0x0F)]) + rest[7 * i:7 * i + 7].ljust(7, pad) for i in range((len(rest) + 6) // 7)]
        self._send(response_id, first, extended)

    def _on_flow_control(self, response_id: int, data: bytes, extended: bool) -> None:
        if data[0] >> 4 != 3 or response_id not in self._pending_isotp:
            return
        for frame in self._pending_isotp.pop(response_id):
            self._send(response_id, frame, extended)

    def _on_frame(self, msg: can.Message) -> None:
        arb, data = msg.arbitration_id, bytes(msg.data)
        if not msg.is_extended_id:
            if self.answer_obd and arb in (obd.FUNCTIONAL_REQUEST_ID_11BIT, 0x7E0):
                if data[0] >> 4 == 3:
                    self._on_flow_control(0x7E8, data, False)
                else:
                    self._on_obd_request(data, False)
            return
        if self.answer_obd and arb == obd.FUNCTIONAL_REQUEST_ID_29BIT:
            self._on_obd_request(data, True)
            return
        if self.answer_obd and arb == (0x18DA00F1 | (self.sa << 8)):
            if data[0] >> 4 == 3:
                self._on_flow_control(obd.RESPONSE_ID_29BIT_BASE | self.sa, data, True)
            else:
                self._on_obd_request(data, True)
            return
        _, pgn, sender, destination = j1939.parse_id(arb)
        if destination not in (self.sa, j1939.GLOBAL_ADDRESS):
            return
        if pgn == j1939.PGN_REQUEST and len(data) >= 3:
            self._on_request(sender, destination, int.from_bytes(data[:3], "little"))
        elif pgn == j1939.PGN_TP_CM and destination == self.sa:
            self._on_tp_cm(sender, data)
