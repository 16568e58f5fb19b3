"""Faults for the field drills: a failing I2C bus, a failing CAN bus, a wall clock that is set.

Each wraps the emulator (or the clock) the daemon already uses, so the production daemon runs
unchanged through the fault: `FaultyI2cBus` raises the errors ``i2c-dev`` gives (EIO for a bus
error, EREMOTEIO for a NACK or a sensor that is gone) and can power-cycle a sensor (its registers
back to their reset values); `FaultyCanBus` makes ``send`` raise `can.CanOperationError` (bus-off,
no ACK) and ``recv`` either raise (interface down) or lose every frame (controller off the bus);
`JumpingClock` is a clock whose CLOCK_REALTIME can be set while CLOCK_MONOTONIC runs on.
"""

from __future__ import annotations

import errno
import os
import threading
import time

import can

from ..clock import Clock


class FaultyI2cBus:
    """An SMBus-shaped wrapper around `EmulatedSMBus` with per-address faults."""

    def __init__(self, bus):
        self.bus = bus
        self.models = bus.models
        self._faults: dict[int, list] = {}
        self._lock = threading.Lock()
        self.raised = 0

    def fail(self, address: int, code: int = errno.EIO, count: int | None = None) -> None:
        """Transactions with ``address`` fail with ``code`` (``count`` times, or until `restore`)."""
        with self._lock:
            self._faults[address] = [code, count]

    def vanish(self, address: int) -> None:
        """The sensor stops acknowledging its address (unplugged, lost power): EREMOTEIO."""
        self.fail(address, errno.EREMOTEIO)

    def restore(self, address: int, power_cycle: bool = False) -> None:
        """The sensor answers again; with ``power_cycle`` its registers are at their reset values."""
        with self._lock:
            self._faults.pop(address, None)
        if power_cycle:
            model = self.bus.devices[address]
            served, overwritten = model.served, model.overwritten
            with self.bus._lock:
                model.__init__(model.address, model.signals, model.clock, model.t0_ns)
            model.served, model.overwritten = served, overwritten

    def _check(self, address: int) -> None:
        with self._lock:
            fault = self._faults.get(address)
            if fault is None:
                return
            code, count = fault
            if count is not None:
                fault[1] -= 1
                if fault[1] <= 0:
                    del self._faults[address]
            self.raised += 1
        raise OSError(code, os.strerror(code))

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        self._check(i2c_addr)
        return self.bus.read_byte_data(i2c_addr, register)

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        self._check(i2c_addr)
        self.bus.write_byte_data(i2c_addr, register, value)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        self._check(i2c_addr)
        return self.bus.read_i2c_block_data(i2c_addr, register, length)

    def close(self) -> None:
        self.bus.close()


class FaultyCanBus:
    """A python-can bus wrapper: ``bus_off`` (sends raise, nothing is received), ``down`` (receive
    raises as a socketcan interface that went down), and optional re-stamping of received frames
    with ``clock``'s wall clock (as the kernel stamps with CLOCK_REALTIME, which can be set)."""

    def __init__(self, bus: can.BusABC, clock: Clock | None = None):
        self.bus = bus
        self.clock = clock
        self._bus_off = False
        self._down = False
        self.failed_sends = 0
        self.lost_frames = 0

    def _lose_pending(self) -> None:
        """Frames that reached the wrapped bus while the controller was off never arrive."""
        while self.bus.recv(0) is not None:
            self.lost_frames += 1

    @property
    def bus_off(self) -> bool:
        return self._bus_off

    @bus_off.setter
    def bus_off(self, value: bool) -> None:
        if self._bus_off and not value:
            self._lose_pending()
        self._bus_off = value

    @property
    def down(self) -> bool:
        return self._down

    @down.setter
    def down(self, value: bool) -> None:
        if self._down and not value:
            self._lose_pending()
        self._down = value

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.bus_off or self.down:
            self.failed_sends += 1
            raise can.CanOperationError("Failed to transmit: [Errno 105] No buffer space available (bus-off)")
        self.bus.send(msg, timeout)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.down:
            self._lose_pending()
            time.sleep(min(timeout or 0.0, 0.05))
            raise can.CanOperationError("Error receiving: [Errno 100] Network is down")
        msg = self.bus.recv(timeout)
        if msg is None:
            return None
        if self.bus_off:
            self.lost_frames += 1
            return None
        if self.clock is not None:
            msg.timestamp = self.clock.realtime_ns() * 1e-9
        return msg

    def shutdown(self) -> None:
        self.bus.shutdown()

    def __getattr__(self, name):
        return getattr(self.bus, name)


class JumpingClock(Clock):
    """A `Clock` whose wall clock can be set (``jump(delta_ns)``); monotonic time is unaffected."""

    def __init__(self, scale: float = 1.0):
        super().__init__(scale)
        self.wall_jump_ns = 0

    def jump(self, delta_ns: int) -> None:
        self.wall_jump_ns += int(delta_ns)

    def realtime_ns(self) -> int:
        return super().realtime_ns() + self.wall_jump_ns


def faulty_devices(signals, clock: Clock, restamp_can: bool = False, **kwargs):
    """`EmulatedDevices` whose CAN bus and I2C bus the daemon gets wrapped in `FaultyCanBus` and
    `FaultyI2cBus` (``devices.faulty_can``, ``devices.faulty_i2c`` once the daemon opened them)."""
    from .rig import EmulatedDevices

    class FaultyDevices(EmulatedDevices):
        faulty_can: FaultyCanBus | None = None
        faulty_i2c: FaultyI2cBus | None = None

        def can_bus(self, config):
            self.faulty_can = FaultyCanBus(super().can_bus(config), clock if restamp_can else None)
            return self.faulty_can

        def smbus(self, config):
            self.faulty_i2c = FaultyI2cBus(super().smbus(config))
            return self.faulty_i2c

    return FaultyDevices(signals, clock, **kwargs)
