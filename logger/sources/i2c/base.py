"""The I2C seam and the source task that polls one driver through the bus's executor.

A bus object is SMBus-shaped: ``read_byte_data(addr, reg)``, ``write_byte_data(addr, reg,
value)``, ``read_i2c_block_data(addr, reg, length)`` (smbus2.SMBus on the Pi, an emulator in
tests). All transactions of one bus run in one thread, so they never interleave and never block the
event loop.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Protocol

from haulprofile import contract
from ...clock import Clock
from ...diagnostics import worth_saying
from ..base import Source

AUTO_INCREMENT = 0x80
"""Sub-address MSB that makes ST sensors (LPS25HB, HTS221, LSM9DS1 magnetometer) auto-increment."""
LOST_AFTER_ERRORS = 3
"""Consecutive failed polls after which a sensor counts as lost (unplugged, browned out)."""
REPROBE_INTERVAL_S = 1.0
"""How often a lost sensor is probed (WHO_AM_I) and, once it answers, configured again [s]."""
HANDOVER_INTERVAL_S = 0.1
"""How often the bus thread hands what it read to the event loop: one wake-up of the loop for
all sensors instead of one per poll that produced a sample [s]."""
RAIL_LIMIT = 32
"""Readings in a row with every byte 0x00 or 0xFF, or at full scale, before a sensor counts as
stuck (a held bus, a dead sensor) or saturated: a real sensor's noise changes its low bits."""


class SMBusLike(Protocol):
    def read_byte_data(self, i2c_addr: int, register: int) -> int: ...

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None: ...

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]: ...


class SensorMissing(Exception):
    """WHO_AM_I did not answer or answered the wrong id."""


class Driver:
    """A sensor on an SMBus-shaped bus; ``poll()`` returns ``[(topic, payload, t_mono_ns, records)]``."""

    name = "sensor"
    who_am_i_register = 0x0F
    who_am_i = 0x00
    poll_interval_s = 0.1

    def __init__(self, bus: SMBusLike, address: int, clock: Clock):
        self.bus = bus
        self.address = address
        self.clock = clock
        self.overruns = 0
        self.rail_run = 0
        """Consecutive readings at a rail (`RAIL_LIMIT`); ``rail_why`` says which."""
        self.rail_why = ""
        self.railed = False

    def note_reading(self, block, saturated: bool = False) -> None:
        """Count a reading whose bytes are all 0x00 or all 0xFF, or that is at full scale."""
        stuck = not any(block) or all(b == 0xFF for b in block)
        if stuck or saturated:
            self.rail_run += 1
            self.rail_why = "every byte 0x00 or 0xFF (a held bus or a dead sensor)" if stuck else "at full scale"
        else:
            self.rail_run = 0

    def probe(self) -> None:
        try:
            found = self.bus.read_byte_data(self.address, self.who_am_i_register)
        except OSError as exc:
            raise SensorMissing(f"{self.name} at {self.address:#04x} does not answer ({exc})") from None
        if found != self.who_am_i:
            raise SensorMissing(f"{self.name} at {self.address:#04x}: WHO_AM_I {found:#04x}, "
                                f"expected {self.who_am_i:#04x}")

    def configure(self) -> None:
        raise NotImplementedError

    def poll(self) -> list:
        raise NotImplementedError

    def flush(self) -> list:
        """What the driver still holds (batched samples), in `poll`'s format; called at the end."""
        return []

    def channel_metadata(self) -> dict[str, dict[str, str]]:
        return {}


class RecordBatch:
    """Packed records of one sensor topic (contract 2), handed out as one message once they
    span ``batch_s`` of samples: a message per second instead of one per sample."""

    def __init__(self, topic: contract.Topic, period_ns: int, batch_s: float):
        self.topic = topic
        self._pack = contract.record_struct(topic).pack
        self._batch_records = max(1, round(batch_s * 1e9 / period_ns))
        self._pending = bytearray()
        self._count = 0

    def add(self, *fields) -> list:
        """One record (the dtype's fields in order); `flush`'s output once the batch is full."""
        self._pending += self._pack(*fields)
        self._count += 1
        return self.flush() if self._count >= self._batch_records else []

    def flush(self) -> list:
        output = packed_output(self.topic, self._pending, self._count)
        self._count = 0
        return output


def packed_output(topic: contract.Topic, pending: bytearray, count: int) -> list:
    """`Driver.poll`'s output of ``count`` packed records held in ``pending`` (emptied): one
    message stamped with its first record's time, or nothing."""
    if not count:
        return []
    payload = bytes(pending)
    pending.clear()
    return [(topic, payload, contract.first_time_ns(payload), count)]


def s16(lo: int, hi: int) -> int:
    value = lo | (hi << 8)
    return value - 0x10000 if value & 0x8000 else value


class I2cBusSource(Source):
    """All sensors of one I2C bus, polled by one thread (transactions never interleave).

    Each driver is polled every ``driver.poll_interval_s``; results reach the event loop in one
    hand-over every ``HANDOVER_INTERVAL_S`` (emulated time). Stats per sensor are in ``stats.extra``.
    A failed transaction (EIO, NACK) is counted; after ``LOST_AFTER_ERRORS`` in a row the sensor is
    lost and probed every ``REPROBE_INTERVAL_S``; when it answers it is configured again (a sensor
    that lost power comes back with its registers reset) and polled as before.
    """

    name = "i2c"

    def __init__(self, queue, clock, drivers: list[Driver], say=None):
        super().__init__(queue, clock, say)
        self.drivers = drivers
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._failing = {driver.name: 0 for driver in drivers}
        for driver in drivers:
            self.stats.extra[driver.name] = {"records": 0, "overruns": 0, "errors": 0, "state": "running"}

    def _reprobe(self, driver: Driver) -> str | None:
        try:
            driver.probe()
            driver.configure()
        except (SensorMissing, OSError):
            return None
        self._failing[driver.name] = 0
        return "back"

    def _poll_round(self, due: dict, now_ns: int) -> list:
        """``[(sensor, outputs, overruns, error, event)]``; event is ``"lost"``, ``"back"`` or None."""
        results = []
        for driver in self.drivers:
            if now_ns < due[driver.name]:
                continue
            if self._failing[driver.name] >= LOST_AFTER_ERRORS:
                due[driver.name] = now_ns + int(REPROBE_INTERVAL_S * 1e9)
                if self._reprobe(driver):
                    results.append((driver.name, [], 0, None, "back"))
                continue
            due[driver.name] = max(due[driver.name] + int(driver.poll_interval_s * 1e9), now_ns - 1_000_000)
            event = None
            try:
                out, error = driver.poll(), None
                self._failing[driver.name] = 0
            except OSError as exc:
                out, error = [], exc
                self._failing[driver.name] += 1
                if self._failing[driver.name] == LOST_AFTER_ERRORS:
                    event = "lost"
            overruns, driver.overruns = driver.overruns, 0
            if event is None and not driver.railed and driver.rail_run >= RAIL_LIMIT:
                driver.railed, event = True, "stuck"
            elif event is None and driver.railed and driver.rail_run == 0:
                driver.railed, event = False, "back"
            if out or overruns or error or event:
                results.append((driver.name, out, overruns, error, event))
        return results

    def _bus_thread(self) -> None:
        clock = self.clock
        for driver in self.drivers:
            try:
                driver.configure()
            except OSError:
                self._failing[driver.name] = LOST_AFTER_ERRORS
        now = clock.monotonic_ns()
        due = {d.name: now for d in self.drivers}
        tick_ns = int(min(d.poll_interval_s for d in self.drivers) * 1e9)
        handover_ns = int(HANDOVER_INTERVAL_S * 1e9)
        next_tick = next_handover = now
        pending: list = []
        while not self._stop.is_set():
            now = clock.monotonic_ns()
            pending += self._poll_round(due, now)
            if pending and now >= next_handover:
                self._loop.call_soon_threadsafe(self._emit_all, pending)
                pending = []
                next_handover = now + handover_ns
            next_tick += tick_ns  # slower sensors are polled on the fastest one's ticks: one wake-up
            wait_ns = next_tick - clock.monotonic_ns()
            if wait_ns > 0:
                clock.thread_sleep(wait_ns * 1e-9)
            else:
                next_tick = clock.monotonic_ns()
        final = pending + self._poll_round({d.name: 0 for d in self.drivers}, clock.monotonic_ns())
        final += [(d.name, out, 0, None, None) for d in self.drivers if (out := d.flush())]
        if final:
            self._loop.call_soon_threadsafe(self._emit_all, final)

    def _emit_all(self, results: list) -> None:
        for name, out, overruns, error, event in results:
            sensor = self.stats.extra[name]
            for topic, payload, t_mono_ns, records in out:
                self.emit(topic, payload, t_mono_ns, records)
                sensor["records"] += records
            self.stats.drops += overruns
            sensor["overruns"] += overruns
            if error is not None:
                self.stats.errors += 1
                sensor["errors"] += 1
                if worth_saying(sensor["errors"]):
                    self.say(f"{name}: I2C error {error} ({sensor['errors']} so far)")
            if event == "lost":
                sensor["state"] = "lost"
                self.say(f"{name}: lost after {LOST_AFTER_ERRORS} failed reads ({error}); "
                         f"probing every {REPROBE_INTERVAL_S:g} s")
            elif event == "stuck":
                driver = next(d for d in self.drivers if d.name == name)
                sensor["state"] = "stuck" if driver.rail_why != "at full scale" else "saturated"
                self.say(f"{name}: {driver.rail_run} readings in a row {driver.rail_why}; logged, but not "
                         "trustworthy until it reads again")
            elif event == "back":
                was = sensor["state"]
                sensor["state"] = "running"
                self.say(f"{name}: answers again, configured and polled" if was == "lost"
                         else f"{name}: reads plausible values again")

    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    async def run(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._thread = threading.Thread(target=self._bus_thread, name="i2c-bus", daemon=True)
        self._thread.start()
        self.stats.state = "running"
        while True:
            await self.clock.sleep(1.0)
            if not self._thread.is_alive():
                self.stats.state = "bus thread stopped"
                raise RuntimeError("I2C bus thread stopped")

    def stop_thread(self) -> None:
        """Ask the bus thread to stop after its current poll (`close` also waits for it)."""
        self._stop.set()

    async def close(self) -> None:
        self.stop_thread()
        if self._thread is not None:
            await asyncio.get_running_loop().run_in_executor(None, self._thread.join, 5.0)
        await asyncio.sleep(0)
