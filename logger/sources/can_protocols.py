"""The requests the logger makes on CAN: OBD-II mode 01 polling and J1939 PGN requests.

Responses are not decoded here (the frames are logged raw); the poller only matches a response
to its request to count answers and timeouts and to notice when no ECU answers at all.
"""

from __future__ import annotations

import asyncio

from .. import j1939, obd
from ..config import J1939Section, ObdSection


class ObdPoller:
    """Round-robin mode 01 requests at ``rate_hz`` (SAE J1979 over ISO 15765-4).

    After ``failed_rounds_before_probe`` rounds without any answer the poller stops loading the
    bus and sends one probe every ``probe_interval_s`` until an ECU answers again.
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
        self._waiting: asyncio.Future | None = None
        self._expect_pid: int | None = None
        self._consecutive_timeouts = 0

    def stats(self) -> dict:
        return {"obd_requests": self.requests, "obd_responses": self.responses, "obd_timeouts": self.timeouts,
                "obd_state": "probing (no ECU answers OBD-II)" if self.probing else "polling"}

    def on_response(self, arbitration_id: int, payload: bytes) -> None:
        """Called in the loop for each reassembled response (any ECU)."""
        if len(payload) < 2 or payload[0] != obd.SERVICE_CURRENT_DATA + obd.POSITIVE_RESPONSE_OFFSET:
            return
        if self._waiting is not None and not self._waiting.done() and payload[1] == self._expect_pid:
            self._waiting.set_result(payload)

    async def _request(self, pids: list[int]) -> bool:
        data = bytes([1 + len(pids), obd.SERVICE_CURRENT_DATA, *pids]).ljust(8, bytes([obd.PAD_BYTE]))
        loop = asyncio.get_running_loop()
        self._waiting = loop.create_future()
        self._expect_pid = pids[0]
        if not self.source.guard.send(self.request_id, data, self.extended):
            self._waiting = None
            return False
        self.requests += 1
        waiting = self._waiting
        timer = loop.call_later(self.source.clock.real_seconds(self.section.timeout_s),
                                lambda: waiting.done() or waiting.set_result(None))
        try:
            answer = await waiting
        finally:
            timer.cancel()
            self._waiting = None
        if answer is None:
            self.timeouts += 1
            self._consecutive_timeouts += 1
            return False
        self.responses += 1
        self._consecutive_timeouts = 0
        return True

    async def run(self) -> None:
        clock = self.source.clock
        period_ns = int(1e9 / self.section.rate_hz)
        give_up_after = self.section.failed_rounds_before_probe * len(self.groups)
        next_ns = clock.monotonic_ns()
        index = 0
        while True:
            if self.probing:
                if await self._request(self.groups[0]):
                    self.probing = False
                    self.source.say("an ECU answers OBD-II again: polling resumed")
                    next_ns = clock.monotonic_ns()
                else:
                    await clock.sleep(self.section.probe_interval_s)
                continue
            await self._request(self.groups[index])
            index = (index + 1) % len(self.groups)
            if self._consecutive_timeouts >= give_up_after:
                self.probing = True
                self.source.say(f"no ECU answered {self._consecutive_timeouts} OBD-II requests: "
                                f"probing every {self.section.probe_interval_s:g} s instead of polling")
                continue
            next_ns += period_ns
            now = clock.monotonic_ns()
            if next_ns < now:
                next_ns = now
            await clock.sleep_until_ns(next_ns)


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
