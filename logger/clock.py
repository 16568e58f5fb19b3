"""The logger's clocks: CLOCK_MONOTONIC and CLOCK_REALTIME in integer ns, optionally time-scaled.

On the truck the scale is 1 and these are the kernel clocks. In emulation the daemon and the
device emulators share one `Clock` whose time runs ``scale`` times faster than the real one, so a
10-minute drive can be logged in less time and still carries the drive's own time stamps.
"""

from __future__ import annotations

import asyncio
import time

WALL_CLOCK_JUMP_NS = 1_000_000_000
"""A change of (realtime - monotonic) larger than this is a wall-clock jump (GPS or NTP setting the
time after boot): the offset between the clocks is taken again; monotonic time stays the time base [ns]."""


class Clock:
    """Monotonic and wall-clock time [ns]; ``scale`` emulated seconds pass per real second."""

    def __init__(self, scale: float = 1.0):
        self.scale = float(scale)
        self._real_mono0 = time.monotonic_ns()
        self._real_unix0 = time.time_ns()

    def monotonic_ns(self) -> int:
        if self.scale == 1.0:
            return time.monotonic_ns()
        return self._real_mono0 + int((time.monotonic_ns() - self._real_mono0) * self.scale)

    def realtime_ns(self) -> int:
        if self.scale == 1.0:
            return time.time_ns()
        return self._real_unix0 + int((time.monotonic_ns() - self._real_mono0) * self.scale)

    def mono_offset_ns(self) -> int:
        """realtime - monotonic [ns], to map kernel (realtime) frame stamps to monotonic time."""
        return self.realtime_ns() - self.monotonic_ns()

    def mono_ns_from_unix_s(self, unix_s: float, offset_ns: int) -> int:
        """Monotonic time [ns] of a wall-clock stamp [s] (as python-can gives) using ``offset_ns``."""
        if self.scale == 1.0:
            return int(unix_s * 1e9) - offset_ns
        real_elapsed_ns = int(unix_s * 1e9) - self._real_unix0
        return self._real_mono0 + int(real_elapsed_ns * self.scale)

    def real_seconds(self, emulated_s: float) -> float:
        return emulated_s / self.scale

    async def sleep(self, emulated_s: float) -> None:
        await asyncio.sleep(max(emulated_s, 0.0) / self.scale)

    async def sleep_until_ns(self, t_mono_ns: int) -> None:
        await asyncio.sleep(max(t_mono_ns - self.monotonic_ns(), 0) * 1e-9 / self.scale)

    def thread_sleep(self, emulated_s: float) -> None:
        time.sleep(max(emulated_s, 0.0) / self.scale)
