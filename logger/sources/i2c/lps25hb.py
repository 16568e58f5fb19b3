"""ST LPS25HB barometer (datasheet DocID023722 rev 6): pressure 4096 LSB/hPa, temperature 42.5 + raw/480 degC."""

from __future__ import annotations

from ... import contract
from .base import AUTO_INCREMENT, Driver

WHO_AM_I_VALUE = 0xBD
CTRL_REG1 = 0x20
STATUS_REG = 0x27
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
        self.poll_interval_s = 0.5 / odr_hz

    def configure(self) -> None:
        self.bus.write_byte_data(self.address, CTRL_REG1,
                                 CTRL_REG1_PD | (ODR_CODE[self.odr_hz] << 4) | CTRL_REG1_BDU)

    def poll(self) -> list:
        status = self.bus.read_byte_data(self.address, STATUS_REG)
        if status & STATUS_P_OR:
            self.overruns += 1
        if not status & STATUS_P_DA:
            return []
        t_mono_ns = self.clock.monotonic_ns()
        b = self.bus.read_i2c_block_data(self.address, PRESS_OUT_XL | AUTO_INCREMENT, 5)
        p_raw = b[0] | (b[1] << 8) | (b[2] << 16)
        if p_raw & 0x800000:
            p_raw -= 1 << 24
        t_raw = b[3] | (b[4] << 8)
        if t_raw & 0x8000:
            t_raw -= 1 << 16
        record = {"t_mono_ns": t_mono_ns, "pressure_pa": pressure_pa(p_raw), "temperature_c": temperature_c(t_raw),
                  "pressure_raw": p_raw, "temperature_raw": t_raw}
        return [(contract.BAROMETER, contract.encode_json(record), t_mono_ns, 1)]
