"""ST HTS221 humidity sensor (datasheet DocID026333 rev 4, TN1218): factory calibration applied.

Relative humidity and temperature are linear interpolations between the two factory calibration
points stored in registers 0x30-0x3F (H0/H1 at T0/T1). Samples go out as packed ``/humidity``
records, one message per ``batch_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

from haulprofile import contract
from .base import AUTO_INCREMENT, Driver, RecordBatch, s16

WHO_AM_I_VALUE = 0xBC
CTRL_REG1 = 0x20
STATUS_REG = 0x27
HUMIDITY_OUT_L = 0x28
CALIB_START = 0x30
STATUS_H_DA = 0x02
ODR_CODE = {1.0: 0b01, 7.0: 0b10, 12.5: 0b11}


@dataclass(frozen=True)
class Calibration:
    """Factory calibration: two humidity points [%rH] and two temperature points [degC] with their counts."""

    h0_rh: float
    h1_rh: float
    h0_t0_out: int
    h1_t0_out: int
    t0_degc: float
    t1_degc: float
    t0_out: int
    t1_out: int

    @classmethod
    def from_registers(cls, b: list[int]) -> "Calibration":
        """From the 16 bytes at 0x30..0x3F (TN1218 section 2)."""
        msb = b[0x35 - 0x30]
        return cls(
            h0_rh=b[0] / 2.0, h1_rh=b[1] / 2.0,
            t0_degc=(((msb & 0x03) << 8) | b[2]) / 8.0, t1_degc=(((msb & 0x0C) << 6) | b[3]) / 8.0,
            h0_t0_out=s16(b[6], b[7]), h1_t0_out=s16(b[10], b[11]),
            t0_out=s16(b[12], b[13]), t1_out=s16(b[14], b[15]))

    def humidity_pct(self, raw: int) -> float:
        """Relative humidity [%] (TN1218 eq. 1), clipped to 0-100 as the note says."""
        h = self.h0_rh + (self.h1_rh - self.h0_rh) * (raw - self.h0_t0_out) / (self.h1_t0_out - self.h0_t0_out)
        return min(max(h, 0.0), 100.0)

    def temperature_c(self, raw: int) -> float:
        """Temperature [degC] (TN1218 eq. 2)."""
        return self.t0_degc + (self.t1_degc - self.t0_degc) * (raw - self.t0_out) / (self.t1_out - self.t0_out)


class Hts221(Driver):
    name = "hts221"
    who_am_i = WHO_AM_I_VALUE

    def __init__(self, bus, address: int, clock, odr_hz: float = 12.5, batch_s: float = 1.0):
        super().__init__(bus, address, clock)
        self.odr_hz = odr_hz
        self.poll_interval_s = 0.25 / odr_hz
        self.calibration: Calibration | None = None
        self.batch = RecordBatch(contract.HUMIDITY, int(1e9 / odr_hz), batch_s)

    def configure(self) -> None:
        self.calibration = Calibration.from_registers(
            self.bus.read_i2c_block_data(self.address, CALIB_START | AUTO_INCREMENT, 16))
        self.bus.write_byte_data(self.address, CTRL_REG1, 0x80 | 0x04 | ODR_CODE[self.odr_hz])

    def poll(self) -> list:
        status = self.bus.read_byte_data(self.address, STATUS_REG)
        if not status & STATUS_H_DA:
            return []
        t_mono_ns = self.clock.monotonic_ns()
        b = self.bus.read_i2c_block_data(self.address, HUMIDITY_OUT_L | AUTO_INCREMENT, 4)
        self.note_reading(b)
        h_raw, t_raw = s16(b[0], b[1]), s16(b[2], b[3])
        return self.batch.add(t_mono_ns, self.calibration.humidity_pct(h_raw), self.calibration.temperature_c(t_raw),
                              h_raw, t_raw, 0)

    def flush(self) -> list:
        return self.batch.flush()
