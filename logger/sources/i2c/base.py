"""The I2C seam and the source task that polls one driver through the bus's executor.

A bus object is SMBus-shaped: ``read_byte_data(addr, reg)``, ``write_byte_data(addr, reg,
value)``, ``read_i2c_block_data(addr, reg, length)`` (smbus2.SMBus on the Pi, an emulator in
tests). All transactions of one bus run in one single-thread executor, so they never interleave
and never block the event loop.
"""

from __future__ import annotations

import asyncio
from concurrent.futures import ThreadPoolExecutor
from typing import Protocol

from ...clock import Clock
from ..base import Source

AUTO_INCREMENT = 0x80
"""Sub-address MSB that makes ST sensors (LPS25HB, HTS221, LSM9DS1 magnetometer) auto-increment."""


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

    def channel_metadata(self) -> dict[str, dict[str, str]]:
        return {}


def s16(lo: int, hi: int) -> int:
    value = lo | (hi << 8)
    return value - 0x10000 if value & 0x8000 else value


class I2cSensorSource(Source):
    """Polls one `Driver` every ``driver.poll_interval_s`` in the bus executor."""

    def __init__(self, queue, clock, driver: Driver, executor: ThreadPoolExecutor, say=None):
        super().__init__(queue, clock, say)
        self.driver = driver
        self.name = driver.name
        self.executor = executor

    def _emit_all(self, out: list) -> None:
        for topic, payload, t_mono_ns, records in out:
            self.emit(topic, payload, t_mono_ns, records)
        self.stats.drops += self.driver.overruns
        self.stats.extra["sensor_overruns"] = self.stats.extra.get("sensor_overruns", 0) + self.driver.overruns
        self.driver.overruns = 0

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self.executor, self.driver.configure)
        period_ns = int(self.driver.poll_interval_s * 1e9)
        next_ns = self.clock.monotonic_ns()
        self.stats.state = "running"
        consecutive_errors = 0
        while True:
            poll = loop.run_in_executor(self.executor, self.driver.poll)
            try:
                out = await asyncio.shield(poll)
                consecutive_errors = 0
            except asyncio.CancelledError:
                try:
                    self._emit_all(await poll)  # a read in flight has already emptied the FIFO: log it
                except OSError:
                    pass
                raise
            except OSError as exc:
                self.stats.errors += 1
                consecutive_errors += 1
                if consecutive_errors in (1, 100):
                    self.say(f"I2C error: {exc}")
                out = []
            self._emit_all(out)
            next_ns += period_ns
            now = self.clock.monotonic_ns()
            if next_ns < now:
                next_ns = now
            await self.clock.sleep_until_ns(next_ns)
