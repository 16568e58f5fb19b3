"""Register-level models of the LPS25HB, HTS221 and LSM9DS1 behind an SMBus-shaped object.

Each model keeps a 256-byte register file, produces samples at its configured output data rate on
the emulation clock (values from a `TimeSeries`), sets and clears the status bits as the
datasheets describe (data-ready cleared by reading the output's high byte, overrun when a sample
replaces an unread one, LSM9DS1 FIFO in continuous mode with FSS/OVRN) and records every sample a
driver actually read in ``served`` so tests can compare the log with it.
"""

from __future__ import annotations

import collections
import errno
import threading

import numpy as np

from haulprofile import contract

from ..clock import Clock
from ..sources.i2c import hts221 as hts, lps25hb as lps, lsm9ds1 as lsm
from .signals import TimeSeries

LPS_ODR = {code: hz for hz, code in lps.ODR_CODE.items()}
HTS_ODR = {code: hz for hz, code in hts.ODR_CODE.items()}
LSM_ODR = {code: hz for hz, code in lsm.ODR_CODE.items()}
MAG_ODR = {code: hz for hz, code in lsm.MAG_ODR_CODE.items()}


def _le(value: int, n: int) -> list[int]:
    return list((int(value) & ((1 << (8 * n)) - 1)).to_bytes(n, "little"))


class RegisterDevice:
    """A register file with auto-increment policy and a sample clock."""

    who_am_i = 0
    increment_on_msb = True

    def __init__(self, address: int, signals: TimeSeries, clock: Clock, t0_ns: int):
        self.address = address
        self.signals = signals
        self.clock = clock
        self.t0_ns = t0_ns
        self.regs = bytearray(256)
        self.regs[0x0F] = self.who_am_i
        self.odr_hz = 0.0
        self.on_since_ns: int | None = None
        self.produced = 0
        self.overwritten = 0
        self.served: list = []

    def power_on(self, odr_hz: float) -> None:
        self.odr_hz = odr_hz
        self.on_since_ns = self.clock.monotonic_ns()
        self.produced = 0

    def advance(self, now_ns: int) -> None:
        if self.on_since_ns is None or not self.odr_hz:
            return
        due = int((now_ns - self.on_since_ns) * self.odr_hz // 1_000_000_000)
        if due > self.produced:
            first = self.produced
            self.produced = due
            self.new_samples(first, due)

    def sample_time_s(self, k) -> np.ndarray | float:
        """Signal time [s] of sample ``k`` (array or scalar)."""
        return (self.on_since_ns - self.t0_ns) * 1e-9 + np.asarray(k) / self.odr_hz

    def new_samples(self, first: int, end: int) -> None:
        raise NotImplementedError

    def read(self, register: int) -> int:
        return self.regs[register]

    def write(self, register: int, value: int) -> None:
        self.regs[register] = value & 0xFF

    def block(self, register: int, length: int) -> list[int]:
        increment = bool(register & 0x80) if self.increment_on_msb else self.auto_increment()
        register &= 0x7F
        return [self.read(register + i if increment else register) for i in range(length)]

    def auto_increment(self) -> bool:
        return True


class Lps25hbModel(RegisterDevice):
    """Pressure/temperature with data-ready bits, or the 32-slot FIFO (stream mode) when enabled.

    Model of the FIFO: a slot holds one pressure and temperature pair; reading TEMP_OUT_H (0x2C),
    the last byte of a 5-byte PRESS_OUT/TEMP_OUT block read, frees the slot. When the FIFO is full
    the oldest slot is overwritten (stream mode) and FULL_FIFO is set.
    """

    who_am_i = lps.WHO_AM_I_VALUE

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.fifo: collections.deque = collections.deque()

    def fifo_on(self) -> bool:
        return bool(self.regs[lps.CTRL_REG2] & lps.CTRL_REG2_FIFO_EN) and \
            (self.regs[lps.FIFO_CTRL] >> 5) == lps.FIFO_MODE_STREAM

    def write(self, register: int, value: int) -> None:
        super().write(register, value)
        if register == lps.CTRL_REG1:
            odr = LPS_ODR.get((value >> 4) & 0x7, 0.0)
            if value & lps.CTRL_REG1_PD and odr:
                self.power_on(odr)

    def _raw(self, t_s: float) -> tuple[int, int]:
        p_raw = int(round(self.signals.value("pressure_pa", t_s, 101325.0) / 100.0 * 4096.0))
        t_raw = int(round((self.signals.value("temperature_c", t_s, 20.0) - 42.5) * 480.0))
        return p_raw, t_raw

    def _show(self, p_raw: int, t_raw: int) -> None:
        self.regs[0x28:0x2B] = bytes(_le(p_raw, 3))
        self.regs[0x2B:0x2D] = bytes(_le(t_raw, 2))

    def new_samples(self, first: int, end: int) -> None:
        if self.fifo_on():
            for k in range(max(first, end - lps.FIFO_DEPTH), end):
                if len(self.fifo) >= lps.FIFO_DEPTH:
                    self.fifo.popleft()
                    self.overwritten += 1
                self.fifo.append(self._raw(float(self.sample_time_s(k))))
            self.overwritten += max(0, (end - first) - lps.FIFO_DEPTH)
            self._show(*self.fifo[0])
            return
        unread = bool(self.regs[lps.STATUS_REG] & lps.STATUS_P_DA)
        lost = (end - first - 1) + (1 if unread else 0)
        if lost:
            self.overwritten += lost
            self.regs[lps.STATUS_REG] |= lps.STATUS_P_OR | 0x10
        self._current = self._raw(float(self.sample_time_s(end - 1)))
        self._show(*self._current)
        self.regs[lps.STATUS_REG] |= lps.STATUS_P_DA | 0x01

    def read(self, register: int) -> int:
        if register == lps.FIFO_STATUS:
            n = len(self.fifo)
            return (lps.FIFO_STATUS_FULL if n >= lps.FIFO_DEPTH else 0) | \
                (lps.FIFO_STATUS_EMPTY if n == 0 else 0) | (n & lps.FIFO_STATUS_FSS)
        value = self.regs[register]
        if self.fifo_on():
            if register == 0x2C and self.fifo:
                self.served.append(self.fifo.popleft())
                if self.fifo:
                    self._show(*self.fifo[0])
            return value
        if register == 0x2A and self.regs[lps.STATUS_REG] & lps.STATUS_P_DA:
            self.regs[lps.STATUS_REG] &= ~(lps.STATUS_P_DA | lps.STATUS_P_OR) & 0xFF
            self.served.append(self._current)
        elif register == 0x2C:
            self.regs[lps.STATUS_REG] &= ~0x11 & 0xFF
        return value


HTS221_CALIBRATION = bytes([
    66, 151,            # H0_rH_x2 (33 %), H1_rH_x2 (75.5 %)
    80, 0x19,           # T0_degC_x8 (10.0), T1_degC_x8 low byte
    0xFF, 0x04,         # reserved, T1/T0 msb: T1.9..8 = 01 -> T1 = 0x119 / 8 = 35.125 degC
    *_le(-4000, 2), 0, 0, *_le(9000, 2),   # H0_T0_OUT, reserved, H1_T0_OUT
    *_le(-500, 2), *_le(3500, 2),          # T0_OUT, T1_OUT
])
"""Factory calibration bytes for registers 0x30..0x3F of the emulated HTS221."""


class Hts221Model(RegisterDevice):
    who_am_i = hts.WHO_AM_I_VALUE

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.regs[0x30:0x40] = HTS221_CALIBRATION
        self.calibration = hts.Calibration.from_registers(list(HTS221_CALIBRATION))

    def write(self, register: int, value: int) -> None:
        super().write(register, value)
        if register == hts.CTRL_REG1 and value & 0x80 and HTS_ODR.get(value & 0x3):
            self.power_on(HTS_ODR[value & 0x3])

    def new_samples(self, first: int, end: int) -> None:
        unread = bool(self.regs[hts.STATUS_REG] & hts.STATUS_H_DA)
        self.overwritten += (end - first - 1) + (1 if unread else 0)
        c = self.calibration
        t_s = float(self.sample_time_s(end - 1))
        h = self.signals.value("relative_humidity_pct", t_s, 50.0)
        t = self.signals.value("temperature_c", t_s, 20.0)
        h_raw = int(round(c.h0_t0_out + (h - c.h0_rh) * (c.h1_t0_out - c.h0_t0_out) / (c.h1_rh - c.h0_rh)))
        t_raw = int(round(c.t0_out + (t - c.t0_degc) * (c.t1_out - c.t0_out) / (c.t1_degc - c.t0_degc)))
        h_raw, t_raw = (int(np.clip(v, -32768, 32767)) for v in (h_raw, t_raw))
        self.regs[0x28:0x2A] = bytes(_le(h_raw, 2))
        self.regs[0x2A:0x2C] = bytes(_le(t_raw, 2))
        self.regs[hts.STATUS_REG] |= hts.STATUS_H_DA | 0x01
        self._current = (h_raw, t_raw)

    def read(self, register: int) -> int:
        value = self.regs[register]
        if register == 0x29 and self.regs[hts.STATUS_REG] & hts.STATUS_H_DA:
            self.regs[hts.STATUS_REG] &= ~hts.STATUS_H_DA & 0xFF
            self.served.append(self._current)
        elif register == 0x2B:
            self.regs[hts.STATUS_REG] &= ~0x01 & 0xFF
        return value


IMU_COLUMNS = ("gyro_x_radps", "gyro_y_radps", "gyro_z_radps", "accel_x_mps2", "accel_y_mps2", "accel_z_mps2")
IMU_DEFAULTS = (0.0, 0.0, 0.0, 0.0, 0.0, lsm.STANDARD_GRAVITY)


class Lsm9ds1AgModel(RegisterDevice):
    """Accelerometer+gyroscope with a 32-slot FIFO; reading OUT_Z_H_XL (0x2D) pops a slot. OUT_TEMP
    holds the newest sample's die temperature (``imu_temperature_c``, 25 degC without it).

    Samples are computed ``BLOCK_SAMPLES`` at a time (one numpy pass) and handed out one by one,
    so emulating 952 Hz costs little next to the driver being measured.
    """

    who_am_i = lsm.WHO_AM_I_AG
    increment_on_msb = False
    BLOCK_SAMPLES = 1024

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.regs[lsm.CTRL_REG8] = lsm.CTRL_REG8_IF_ADD_INC
        self.fifo: collections.deque = collections.deque()
        self.overrun = False
        self._block_first = 0
        self._block: list[bytes] = []

    def auto_increment(self) -> bool:
        return bool(self.regs[lsm.CTRL_REG8] & lsm.CTRL_REG8_IF_ADD_INC)

    def write(self, register: int, value: int) -> None:
        super().write(register, value)
        self._block = []  # full scales or the rate may have changed
        if register == lsm.CTRL_REG1_G and LSM_ODR.get(value >> 5):
            self.power_on(LSM_ODR[value >> 5])

    def scales(self) -> np.ndarray:
        g_code = (self.regs[lsm.CTRL_REG1_G] >> 3) & 0x3
        a_code = (self.regs[lsm.CTRL_REG6_XL] >> 3) & 0x3
        gyro = next(lsm.gyro_scale_radps_per_lsb(r) for r, (c, _) in lsm.GYRO_FS.items() if c == g_code)
        accel = next(lsm.accel_scale_mps2_per_lsb(r) for r, (c, _) in lsm.ACCEL_FS.items() if c == a_code)
        return np.array([gyro] * 3 + [accel] * 3)

    def raw_samples(self, first: int, end: int) -> np.ndarray:
        """Output words (gyro xyz, accel xyz, int16) of samples ``first`` to ``end - 1``."""
        t_s = self.sample_time_s(np.arange(first, end))
        idx = np.clip(np.searchsorted(self.signals.time_s, self.signals.time_s[0] + t_s, side="right") - 1,
                      0, len(self.signals.time_s) - 1)
        values = np.column_stack([
            self.signals.columns[name][idx] if name in self.signals.columns else np.full(len(idx), default)
            for name, default in zip(IMU_COLUMNS, IMU_DEFAULTS)])
        return np.clip(np.round(values / self.scales()), -32768, 32767).astype("<i2")

    def _sample_bytes(self, k: int) -> bytes:
        offset = k - self._block_first
        if not 0 <= offset < len(self._block):
            self._block_first, offset = k, 0
            self._block = [row.tobytes() for row in self.raw_samples(k, k + self.BLOCK_SAMPLES)]
        return self._block[offset]

    def new_samples(self, first: int, end: int) -> None:
        temperature_c = self.signals.value("imu_temperature_c", float(self.sample_time_s(end - 1)),
                                           contract.IMU_TEMPERATURE_ZERO_C)
        raw = int(contract.imu_temperature_counts(temperature_c))
        self.regs[lsm.OUT_TEMP_L:lsm.OUT_TEMP_L + 2] = bytes(_le(raw, 2))
        if not self.regs[lsm.CTRL_REG9] & lsm.CTRL_REG9_FIFO_EN:
            row = self._sample_bytes(end - 1)
            self.regs[0x18:0x1E] = row[:6]
            self.regs[0x28:0x2E] = row[6:]
            return
        fifo = self.fifo
        cannot_survive = max(0, end - first - lsm.FIFO_DEPTH)  # pushed out again by the newer ones
        if cannot_survive:
            self.overwritten += cannot_survive
            self.overrun = True
        for k in range(first + cannot_survive, end):
            if len(fifo) >= lsm.FIFO_DEPTH:
                fifo.popleft()
                self.overwritten += 1
                self.overrun = True
            fifo.append(self._sample_bytes(k))

    def block(self, register: int, length: int) -> list[int]:
        if length == 6 and self.fifo and register in (lsm.OUT_X_L_G, lsm.OUT_X_L_XL) and self.auto_increment():
            if register == lsm.OUT_X_L_G:
                return list(self.fifo[0][:6])
            row = self.fifo.popleft()
            self.served.append(row)
            return list(row[6:])
        return super().block(register, length)

    def read(self, register: int) -> int:
        if register == lsm.FIFO_SRC:
            value = min(len(self.fifo), lsm.FIFO_DEPTH) | (lsm.FIFO_SRC_OVRN if self.overrun else 0)
            if len(self.fifo) > (self.regs[lsm.FIFO_CTRL] & 0x1F):
                value |= 0x80
            self.overrun = False
            return value
        if self.fifo and 0x18 <= register <= 0x1D:
            return self.fifo[0][register - 0x18]
        if self.fifo and 0x28 <= register <= 0x2D:
            value = self.fifo[0][6 + register - 0x28]
            if register == 0x2D:
                self.served.append(self.fifo.popleft())
            return value
        return self.regs[register]


class Lsm9ds1MagModel(RegisterDevice):
    who_am_i = lsm.WHO_AM_I_M

    def write(self, register: int, value: int) -> None:
        super().write(register, value)
        if register == lsm.CTRL_REG1_M:
            self.power_on(MAG_ODR[(value >> 2) & 0x7])

    def new_samples(self, first: int, end: int) -> None:
        if self.regs[lsm.STATUS_REG_M] & lsm.STATUS_M_ZYXDA:
            self.overwritten += 1
        self.overwritten += end - first - 1
        t_s = float(self.sample_time_s(end - 1))
        field_t = [self.signals.value(f"magnetic_{a}_t", t_s, d) for a, d in zip("xyz", (20e-6, 0.0, -44e-6))]
        raw = [int(np.clip(round(f / (lsm.MAG_SENSITIVITY_GAUSS * 1e-4)), -32768, 32767)) for f in field_t]
        self.regs[0x28:0x2E] = bytes(b for r in raw for b in _le(r, 2))
        self.regs[lsm.STATUS_REG_M] |= lsm.STATUS_M_ZYXDA
        self._current = tuple(raw)

    def read(self, register: int) -> int:
        value = self.regs[register]
        if register == 0x2D and self.regs[lsm.STATUS_REG_M] & lsm.STATUS_M_ZYXDA:
            self.regs[lsm.STATUS_REG_M] &= ~lsm.STATUS_M_ZYXDA & 0xFF
            self.served.append(self._current)
        return value


class EmulatedSMBus:
    """smbus2.SMBus-shaped access to the emulated devices; a missing address is errno 121 (EREMOTEIO)."""

    def __init__(self, devices: list[RegisterDevice], clock: Clock):
        self.devices = {d.address: d for d in devices}
        self.clock = clock
        self._lock = threading.Lock()
        self.transactions = 0

    def _device(self, address: int) -> RegisterDevice:
        device = self.devices.get(address)
        if device is None:
            raise OSError(errno.EREMOTEIO, "Remote I/O error")
        device.advance(self.clock.monotonic_ns())
        return device

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        with self._lock:
            self.transactions += 1
            return self._device(i2c_addr).block(register, 1)[0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        with self._lock:
            self.transactions += 1
            self._device(i2c_addr).write(register & 0x7F, value)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        if not 1 <= length <= 32:
            raise ValueError("I2C block reads are 1 to 32 bytes")
        with self._lock:
            self.transactions += 1
            return self._device(i2c_addr).block(register, length)

    def close(self) -> None:
        pass


def sensor_board(signals: TimeSeries, clock: Clock, t0_ns: int, lps25hb_address: int = 0x5C,
                 hts221_address: int = 0x5F, lsm9ds1_ag_address: int = 0x6B, lsm9ds1_m_address: int = 0x1E,
                 missing: tuple[str, ...] = ()) -> EmulatedSMBus:
    """An SMBus with the three sensors (as on a Sense-HAT-like board); ``missing`` leaves some out."""
    models = {"lps25hb": Lps25hbModel(lps25hb_address, signals, clock, t0_ns),
              "hts221": Hts221Model(hts221_address, signals, clock, t0_ns),
              "lsm9ds1": Lsm9ds1AgModel(lsm9ds1_ag_address, signals, clock, t0_ns),
              "lsm9ds1_mag": Lsm9ds1MagModel(lsm9ds1_m_address, signals, clock, t0_ns)}
    bus = EmulatedSMBus([m for name, m in models.items() if name not in missing], clock)
    bus.models = models
    return bus
