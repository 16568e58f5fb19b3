"""ST LSM9DS1 (datasheet DocID025715 rev 3): accelerometer+gyroscope through the FIFO, magnetometer.

The FIFO runs in continuous mode; each poll reads FIFO_SRC for the number of unread samples and
then each sample's gyroscope (OUT_X_L_G..) and accelerometer (OUT_X_L_XL..) words, so no sample is
lost between polls. An overrun flag (OVRN) is counted as a drop. Samples are handed to the writer
in batches of ``batch_s`` (one ``/imu`` message per 0.1 s by default). Sample stamps come from a
continuous sample clock (`FifoSampleClock`): evenly spaced at the ODR period, strictly increasing,
kept within the window each FIFO read allows by a bounded correction. Once a second the die's
temperature (OUT_TEMP) is read beside the FIFO, for ``/imu/temperature``: the accelerometer's bias
follows it.
"""

from __future__ import annotations

import math

from haulprofile import contract
from .base import AUTO_INCREMENT, Driver, RecordBatch, packed_output, s16
from .sample_clock import FifoSampleClock

WHO_AM_I_AG = 0x68
WHO_AM_I_M = 0x3D
CTRL_REG1_G = 0x10
OUT_TEMP_L = 0x15
OUT_X_L_G = 0x18
CTRL_REG6_XL = 0x20
CTRL_REG8 = 0x22
CTRL_REG9 = 0x23
OUT_X_L_XL = 0x28
FIFO_CTRL = 0x2E
FIFO_SRC = 0x2F
FIFO_SRC_OVRN = 0x40
FIFO_SRC_FSS = 0x3F
FIFO_DEPTH = 32
FIFO_MODE_CONTINUOUS = 0b110
FIFO_READ_LEVEL = 8
"""The FIFO is read when it holds this many samples (a quarter: 8.4 ms at 952 Hz), so a wake-up of
the bus thread may come 25 ms late before a sample is lost. Read at half full (16) the margin was
17 ms, which the thread missed 2-5 times a minute in the saturated-bus benchmark on a shared
machine (issue 29, docs/logger.md)."""
MAX_POLL_INTERVAL_S = 0.1
"""At low rates the FIFO is read at least this often [s]."""
CTRL_REG8_BDU = 0x40
CTRL_REG8_IF_ADD_INC = 0x04
CTRL_REG9_FIFO_EN = 0x02
TEMP_INTERVAL_S = 1.0
"""How often the temperature is read [s]: a die warms by a few kelvin a minute at most."""
TEMP_BATCH_S = 10.0
"""Readings per `/imu/temperature` message: ten, a message every 10 s."""

CTRL_REG1_M = 0x20
CTRL_REG2_M = 0x21
CTRL_REG3_M = 0x22
STATUS_REG_M = 0x27
OUT_X_L_M = 0x28
STATUS_M_ZYXDA = 0x08

ODR_CODE = {14.9: 0b001, 59.5: 0b010, 119.0: 0b011, 238.0: 0b100, 476.0: 0b101, 952.0: 0b110}
GYRO_FS = {245: (0b00, 8.75e-3), 500: (0b01, 17.50e-3), 2000: (0b11, 70e-3)}
"""FS_G code and sensitivity [dps/LSB]."""
ACCEL_FS = {2: (0b00, 0.061e-3), 16: (0b01, 0.732e-3), 4: (0b10, 0.122e-3), 8: (0b11, 0.244e-3)}
"""FS_XL code and sensitivity [g/LSB]."""
MAG_ODR_CODE = {0.625: 0, 1.25: 1, 2.5: 2, 5.0: 3, 10.0: 4, 20.0: 5, 40.0: 6, 80.0: 7}
MAG_SENSITIVITY_GAUSS = 0.14e-3
"""±4 gauss full scale [gauss/LSB]."""
STANDARD_GRAVITY = 9.80665


def accel_scale_mps2_per_lsb(range_g: int) -> float:
    return ACCEL_FS[range_g][1] * STANDARD_GRAVITY


def gyro_scale_radps_per_lsb(range_dps: int) -> float:
    return math.radians(GYRO_FS[range_dps][1])


class Lsm9ds1(Driver):
    """Accelerometer and gyroscope, both at ``odr_hz``, read from the FIFO."""

    name = "lsm9ds1"
    who_am_i = WHO_AM_I_AG

    def __init__(self, bus, address: int, clock, odr_hz: float = 952.0, accel_range_g: int = 4,
                 gyro_range_dps: int = 245, batch_s: float = 0.1):
        super().__init__(bus, address, clock)
        self.odr_hz = odr_hz
        self.accel_range_g = accel_range_g
        self.gyro_range_dps = gyro_range_dps
        self.poll_interval_s = min(FIFO_READ_LEVEL / odr_hz, MAX_POLL_INTERVAL_S)
        self._period_ns = int(1e9 / odr_hz)
        self.sample_clock = FifoSampleClock(self._period_ns)
        self.batch_ns = int(batch_s * 1e9)
        self._pending = bytearray()
        self._pending_count = 0
        self.temperature = RecordBatch(contract.IMU_TEMPERATURE, int(TEMP_INTERVAL_S * 1e9), TEMP_BATCH_S)
        self._next_temperature_ns: int | None = None

    def configure(self) -> None:
        self.sample_clock.last_ns = None  # a (re)configured FIFO starts a new sample sequence
        w = self.bus.write_byte_data
        odr = ODR_CODE[self.odr_hz]
        w(self.address, CTRL_REG8, CTRL_REG8_BDU | CTRL_REG8_IF_ADD_INC)
        w(self.address, CTRL_REG1_G, (odr << 5) | (GYRO_FS[self.gyro_range_dps][0] << 3))
        w(self.address, CTRL_REG6_XL, (odr << 5) | (ACCEL_FS[self.accel_range_g][0] << 3))
        w(self.address, CTRL_REG9, CTRL_REG9_FIFO_EN)
        w(self.address, FIFO_CTRL, (FIFO_MODE_CONTINUOUS << 5) | (FIFO_DEPTH - 1))

    def channel_metadata(self) -> dict[str, dict[str, str]]:
        return {contract.IMU.name: {
            "sensor": "LSM9DS1", "odr_hz": repr(self.odr_hz),
            "accel_scale_mps2_per_lsb": repr(accel_scale_mps2_per_lsb(self.accel_range_g)),
            "gyro_scale_radps_per_lsb": repr(gyro_scale_radps_per_lsb(self.gyro_range_dps)),
            "accel_range_g": str(self.accel_range_g), "gyro_range_dps": str(self.gyro_range_dps)},
            contract.IMU_TEMPERATURE.name: {"sensor": "LSM9DS1", "register": "OUT_TEMP",
                                            "temperature_lsb_per_c": repr(contract.IMU_TEMPERATURE_LSB_PER_C),
                                            "temperature_zero_c": repr(contract.IMU_TEMPERATURE_ZERO_C)}}

    def poll(self) -> list:
        """Read what the FIFO holds, and the temperature when it is due; hand out one ``/imu`` message
        per ``batch_s`` of samples and one ``/imu/temperature`` message per `TEMP_BATCH_S`."""
        before_ns = self.clock.monotonic_ns()
        src = self.bus.read_byte_data(self.address, FIFO_SRC)
        after_ns = self.clock.monotonic_ns()
        overrun = bool(src & FIFO_SRC_OVRN)
        if overrun:
            self.overruns += 1
        n = src & FIFO_SRC_FSS
        read = self.bus.read_i2c_block_data
        address = self.address
        pack = contract.TIME_STRUCT.pack  # the record's t_mono_ns; the registers' little-endian words follow
        pending = self._pending
        for t_ns in self.sample_clock.stamps(n, before_ns, after_ns, overrun):
            gyro = read(address, OUT_X_L_G, 6)  # gyroscope first: reading OUT_Z_H_XL pops the slot
            pending += pack(t_ns)
            accel = read(address, OUT_X_L_XL, 6)
            self.note_reading(accel + gyro, saturated=_full_scale(accel))
            pending.extend(accel)
            pending.extend(gyro)
        self._pending_count += n
        output = self._read_temperature(after_ns)
        if self._pending_count * self._period_ns >= self.batch_ns:
            output += self._flush_samples()
        return output

    def _read_temperature(self, now_ns: int) -> list:
        """OUT_TEMP once every `TEMP_INTERVAL_S` on average, not once per interval plus a poll's delay
        (block data update keeps its two bytes one reading); after a gap, no burst of catch-up reads."""
        interval_ns = int(TEMP_INTERVAL_S * 1e9)
        if self._next_temperature_ns is None:
            self._next_temperature_ns = now_ns
        if now_ns < self._next_temperature_ns:
            return []
        self._next_temperature_ns += interval_ns
        if self._next_temperature_ns <= now_ns:
            self._next_temperature_ns = now_ns + interval_ns
        low, high = self.bus.read_i2c_block_data(self.address, OUT_TEMP_L, 2)
        raw = s16(low, high)
        return self.temperature.add(self.clock.monotonic_ns(), float(contract.imu_temperature_c(raw)), raw, 0, 0, 0)

    def _flush_samples(self) -> list:
        output = packed_output(contract.IMU, self._pending, self._pending_count)
        self._pending_count = 0
        return output

    def flush(self) -> list:
        return self._flush_samples() + self.temperature.flush()


def _full_scale(accel: list[int]) -> bool:
    """An accelerometer axis at the end of its range (0x7FFF or 0x8000): the truck's acceleration
    is beyond the configured full scale (``i2c.lsm9ds1.accel_range_g``)."""
    return any((accel[i], accel[i + 1]) in ((0xFF, 0x7F), (0x00, 0x80)) for i in (0, 2, 4))


class Lsm9ds1Magnetometer(Driver):
    name = "lsm9ds1_mag"
    who_am_i = WHO_AM_I_M

    def __init__(self, bus, address: int, clock, odr_hz: float = 10.0, batch_s: float = 1.0):
        super().__init__(bus, address, clock)
        self.odr_hz = odr_hz
        self.poll_interval_s = 0.25 / odr_hz
        self.batch = RecordBatch(contract.MAGNETOMETER, int(1e9 / odr_hz), batch_s)

    def configure(self) -> None:
        w = self.bus.write_byte_data
        w(self.address, CTRL_REG1_M, 0x80 | (0b10 << 5) | (MAG_ODR_CODE[self.odr_hz] << 2))
        w(self.address, CTRL_REG2_M, 0x00)
        w(self.address, CTRL_REG3_M, 0x00)

    def poll(self) -> list:
        status = self.bus.read_byte_data(self.address, STATUS_REG_M)
        if not status & STATUS_M_ZYXDA:
            return []
        t_mono_ns = self.clock.monotonic_ns()
        b = self.bus.read_i2c_block_data(self.address, OUT_X_L_M | AUTO_INCREMENT, 6)
        self.note_reading(b)
        raw = [s16(b[0], b[1]), s16(b[2], b[3]), s16(b[4], b[5])]
        return self.batch.add(t_mono_ns, *[r * MAG_SENSITIVITY_GAUSS * 1e-4 for r in raw], *raw, 0)

    def flush(self) -> list:
        return self.batch.flush()
