"""ST LPS25HB barometer (datasheet DocID023722 rev 6): pressure 4096 LSB/hPa, temperature 42.5 + raw/480 degC.

Read through its 32-slot FIFO in stream mode: each poll reads FIFO_STATUS for the number of
unread samples and then that many PRESS_OUT/TEMP_OUT blocks, so a late poll loses nothing; stamps
from the continuous sample clock (`FifoSampleClock`). One packed ``/barometer`` message per FIFO read.
"""

from __future__ import annotations

from haulprofile import contract
from .base import AUTO_INCREMENT, Driver
from .sample_clock import FifoSampleClock

WHO_AM_I_VALUE = 0xBD
CTRL_REG1 = 0x20
CTRL_REG2 = 0x21
CTRL_REG2_FIFO_EN = 0x40
STATUS_REG = 0x27
FIFO_CTRL = 0x2E
FIFO_STATUS = 0x2F
FIFO_MODE_STREAM = 0b010
FIFO_STATUS_FULL = 0x40
FIFO_STATUS_EMPTY = 0x20
FIFO_STATUS_FSS = 0x1F
FIFO_DEPTH = 32
PRESS_OUT_XL = 0x28
STATUS_P_DA = 0x02
STATUS_P_OR = 0x20
CTRL_REG1_PD = 0x80
CTRL_REG1_BDU = 0x04
ODR_CODE = {1.0: 0b001, 7.0: 0b010, 12.5: 0b011, 25.0: 0b100}
"""CTRL_REG1 ODR[2:0] for the output data rates [Hz]."""


def pressure_pa(raw: int) -> float:
    """Pressure [Pa] from the signed 24-bit PRESS_OUT count (4096 LSB/hPa)."""
    return raw / 4096.0 * 100.0


def temperature_c(raw: int) -> float:
    """Temperature [degC] from the signed 16-bit TEMP_OUT count."""
    return 42.5 + raw / 480.0


class Lps25hb(Driver):
    name = "lps25hb"
    who_am_i = WHO_AM_I_VALUE

    def __init__(self, bus, address: int, clock, odr_hz: float = 25.0):
        super().__init__(bus, address, clock)
        self.odr_hz = odr_hz
        self.poll_interval_s = 8.0 / odr_hz
        self._period_ns = int(1e9 / odr_hz)
        self.sample_clock = FifoSampleClock(self._period_ns)

    def configure(self) -> None:
        self.sample_clock.last_ns = None  # a (re)configured FIFO starts a new sample sequence
        w = self.bus.write_byte_data
        w(self.address, CTRL_REG1, CTRL_REG1_PD | (ODR_CODE[self.odr_hz] << 4) | CTRL_REG1_BDU)
        w(self.address, CTRL_REG2, CTRL_REG2_FIFO_EN)
        w(self.address, FIFO_CTRL, FIFO_MODE_STREAM << 5)

    def poll(self) -> list:
        before_ns = self.clock.monotonic_ns()
        status = self.bus.read_byte_data(self.address, FIFO_STATUS)
        after_ns = self.clock.monotonic_ns()
        full = bool(status & FIFO_STATUS_FULL)
        if full:
            self.overruns += 1
            n = FIFO_DEPTH
        else:
            n = status & FIFO_STATUS_FSS
        pack = contract.record_struct(contract.BAROMETER).pack
        payload = bytearray()
        for t_mono_ns in self.sample_clock.stamps(n, before_ns, after_ns, overrun=full):
            b = self.bus.read_i2c_block_data(self.address, PRESS_OUT_XL | AUTO_INCREMENT, 5)
            self.note_reading(b)
            p_raw = b[0] | (b[1] << 8) | (b[2] << 16)
            if p_raw & 0x800000:
                p_raw -= 1 << 24
            t_raw = b[3] | (b[4] << 8)
            if t_raw & 0x8000:
                t_raw -= 1 << 16
            payload += pack(t_mono_ns, pressure_pa(p_raw), temperature_c(t_raw), p_raw, t_raw, 0)
        if not payload:
            return []
        count = len(payload) // contract.BAROMETER.dtype.itemsize
        return [(contract.BAROMETER, bytes(payload), contract.first_time_ns(payload), count)]
