"""The requests the logger makes on CAN: OBD-II mode 01 polling and J1939 PGN requests.

Responses are not decoded here (the frames are logged raw); the poller only matches a response
to its request to count answers and timeouts and to notice when no ECU answers at all.
"""

from __future__ import annotations

import collections

from haulprofile.contract import j1939, obd
from ..config import J1939Section, ObdSection
from ..diagnostics import ordinal, worth_saying


class ObdPoller:
    """Round-robin mode 01 requests at ``rate_hz`` (SAE J1979 over ISO 15765-4).

    Driven by the CAN reader thread: `tick` runs on each of its wake-ups, after the frames that
    arrived meanwhile (answers included, noted by `on_response`) were taken, so polling costs the
    event loop nothing. One request at a time: the next goes out at its slot once the last one
    was answered or ``timeout_s`` passed. After ``failed_rounds_before_probe`` rounds without any
    answer the poller stops loading the bus and sends one probe every ``probe_interval_s`` until
    an ECU answers again. Going to probing and back is said by the diagnostics policy
    (`..diagnostics.SAID_AT`): the first time, then the 100th…; ``give_ups`` counts them all, so
    answers that come and go (a loaded gateway, a time-compressed emulator) are one line, not one
    per spell.
    """

    def __init__(self, source, section: ObdSection):
        self.source = source
        self.section = section
        self.extended = section.addressing == "29bit"
        self.request_id = obd.FUNCTIONAL_REQUEST_ID_29BIT if self.extended else obd.FUNCTIONAL_REQUEST_ID_11BIT
        per = section.pids_per_request
        self.groups = [section.pids[i:i + per] for i in range(0, len(section.pids), per)]
        self.requests = 0
        self.responses = 0
        self.timeouts = 0
        self.probing = False
        self.give_ups = 0
        """Times the poller went from polling to probing (a whole round without an answer)."""
        self._said_give_up = False
        self._answered: collections.deque = collections.deque()
        self._outstanding: int | None = None
        self._sent_ns = 0
        self._consecutive_timeouts = 0
        self._period_ns = int(1e9 / section.rate_hz)
        self._timeout_ns = int(section.timeout_s * 1e9)
        self._give_up_after = section.failed_rounds_before_probe * len(self.groups)
        self._slot_ns: int | None = None
        self._index = 0

    def stats(self) -> dict:
        return {"obd_requests": self.requests, "obd_responses": self.responses, "obd_timeouts": self.timeouts,
                "obd_state": "probing (no ECU answers OBD-II)" if self.probing else "polling",
                "obd_give_ups": self.give_ups}

    def on_response(self, arbitration_id: int, payload: bytes) -> None:
        """A reassembled response from any ECU."""
        if len(payload) >= 2 and payload[0] == obd.SERVICE_CURRENT_DATA + obd.POSITIVE_RESPONSE_OFFSET:
            self._answered.append(payload[1])

    def _settle(self, now_ns: int) -> str:
        """The outstanding request's fate: ``"answered"``, ``"timeout"``, ``"waiting"`` or ``"idle"``."""
        while self._answered:
            if self._answered.popleft() == self._outstanding:
                self._outstanding = None
                self.responses += 1
                self._consecutive_timeouts = 0
                return "answered"
        if self._outstanding is None:
            return "idle"
        if now_ns - self._sent_ns < self._timeout_ns:
            return "waiting"
        self._outstanding = None
        self.timeouts += 1
        self._consecutive_timeouts += 1
        return "timeout"

    def _send(self, pids: list[int], now_ns: int) -> None:
        data = bytes([1 + len(pids), obd.SERVICE_CURRENT_DATA, *pids]).ljust(8, bytes([obd.PAD_BYTE]))
        self._answered.clear()
        if self.source.guard.send(self.request_id, data, self.extended):
            self.requests += 1
            self._outstanding = pids[0]
            self._sent_ns = now_ns

    def tick(self, now_ns: int) -> int:
        """Send what is due at ``now_ns`` [ns]; returns when the poller next has something to do."""
        if self._slot_ns is None:
            self._slot_ns = now_ns
        fate = self._settle(now_ns)
        if fate == "waiting":
            return self._sent_ns + self._timeout_ns
        if self.probing:
            if fate == "answered":
                self.probing = False
                if self._said_give_up:  # the answer to a line that was said
                    self.source.say("an ECU answers OBD-II again: polling resumed")
                self._slot_ns = now_ns
            elif now_ns < self._slot_ns:
                return self._slot_ns
            else:
                self._send(self.groups[0], now_ns)
                self._slot_ns = now_ns + int(self.section.probe_interval_s * 1e9)
                return now_ns + self._timeout_ns
        elif self._consecutive_timeouts >= self._give_up_after:
            self.probing = True
            self.give_ups += 1
            self._said_give_up = worth_saying(self.give_ups)
            if self._said_give_up:
                again = "" if self.give_ups == 1 else f" (the {ordinal(self.give_ups)} time: answers come and go)"
                self.source.say(f"no ECU answered {self._consecutive_timeouts} OBD-II requests{again}: "
                                f"probing every {self.section.probe_interval_s:g} s instead of polling")
            self._slot_ns = now_ns
            return self.tick(now_ns)
        if now_ns < self._slot_ns:
            return self._slot_ns
        self._send(self.groups[self._index], now_ns)
        self._index = (self._index + 1) % len(self.groups)
        self._slot_ns = max(self._slot_ns + self._period_ns, now_ns)
        return self._slot_ns


class J1939Requester:
    """PGN 59904 requests for on-request PGNs (EC1, vehicle weight) every ``request_interval_s``."""

    def __init__(self, source, section: J1939Section):
        self.source = source
        self.section = section
        self.request_id = j1939.make_id(j1939.PGN_REQUEST, section.source_address, 6, section.request_destination)
        self.requests = 0

    def stats(self) -> dict:
        return {"j1939_requests": self.requests}

    async def run(self) -> None:
        while True:
            for pgn in self.section.request_pgns:
                if self.source.guard.send(self.request_id, j1939.request_data(pgn), True):
                    self.requests += 1
                await self.source.clock.sleep(0.05)
            await self.source.clock.sleep(self.section.request_interval_s)
