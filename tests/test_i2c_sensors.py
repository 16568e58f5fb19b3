"""Register-level drivers against the emulated sensors, and their conversions against the
datasheets' formulas written out by hand."""

from __future__ import annotations

import time

import numpy as np
import pytest

from haulprofile import contract
from haulprofile.logger.clock import Clock
from haulprofile.logger.emulators.sensors import HTS221_CALIBRATION, sensor_board
from haulprofile.logger.emulators.signals import TimeSeries
from haulprofile.logger.sources.i2c import lsm9ds1 as lsm
from haulprofile.logger.sources.i2c.base import I2cBusSource, SensorMissing
from haulprofile.logger.sources.i2c.hts221 import Calibration, Hts221
from haulprofile.logger.sources.i2c.lps25hb import Lps25hb, pressure_pa, temperature_c
from haulprofile.logger.sources.i2c.lsm9ds1 import Lsm9ds1, Lsm9ds1Magnetometer


def _records(out) -> list[dict]:
    """Samples of drivers' outputs (packed sensor records, contract 2) as dicts."""
    records = []
    for topic, payload, t_mono_ns, count in out:
        samples = contract.unpack(topic, payload)
        assert len(samples) == count and t_mono_ns == int(samples["t_mono_ns"][0])
        records += [{name: samples[name][k].tolist() for name in samples.dtype.names} for k in range(count)]
    return records


def board(columns=None, missing=()):
    clock = Clock()
    t = np.array([0.0, 1000.0])
    signals = TimeSeries(columns or {"time_s": t, "pressure_pa": np.full(2, 95_123.0),
                                     "temperature_c": np.full(2, 21.3), "relative_humidity_pct": np.full(2, 47.5),
                                     "accel_x_mps2": np.full(2, 1.25), "accel_z_mps2": np.full(2, 9.80665),
                                     "gyro_z_radps": np.full(2, 0.05)})
    return sensor_board(signals, clock, clock.monotonic_ns(), missing=missing), clock


def test_lps25hb_conversions_from_the_datasheet():
    # LPS25HB: pressure [hPa] = PRESS_OUT / 4096, temperature [degC] = 42.5 + TEMP_OUT / 480
    assert pressure_pa(0x3FF58D) == pytest.approx(4191629 / 4096 * 100)
    assert pressure_pa(0x3FF58D) == pytest.approx(102334.7, abs=0.1)
    assert temperature_c(-8068) == pytest.approx(25.69167, abs=1e-5)


def test_lps25hb_reads_every_sample_through_the_fifo():
    bus, clock = board()
    driver = Lps25hb(bus, 0x5C, clock, 25.0)
    driver.probe()
    driver.configure()
    time.sleep(0.5)
    out = driver.poll()
    assert len(out) == 1  # one message per FIFO read
    records = _records(out)
    model = bus.models["lps25hb"]
    assert 10 <= len(records) == len(model.served) == model.produced
    assert records[0]["pressure_raw"] == round(95_123.0 / 100 * 4096)
    assert records[0]["pressure_pa"] == pytest.approx(95_123.0, abs=100 / 4096)
    assert records[0]["temperature_c"] == pytest.approx(21.3, abs=1 / 480)
    stamps = [r["t_mono_ns"] for r in records]
    assert np.allclose(np.diff(stamps), 40e6)


def test_hts221_calibration_interpolates_like_tn1218():
    c = Calibration.from_registers(list(HTS221_CALIBRATION))
    assert (c.h0_rh, c.h1_rh, c.t0_degc, c.t1_degc) == (33.0, 75.5, 10.0, 35.125)
    assert (c.h0_t0_out, c.h1_t0_out, c.t0_out, c.t1_out) == (-4000, 9000, -500, 3500)
    # TN1218: H = H0 + (H1 - H0) * (H_OUT - H0_T0_OUT) / (H1_T0_OUT - H0_T0_OUT)
    assert c.humidity_pct(2500) == pytest.approx(33.0 + 42.5 * 6500 / 13000)
    assert c.temperature_c(1500) == pytest.approx(10.0 + 25.125 * 2000 / 4000)
    assert c.humidity_pct(40000) == 100.0


def test_hts221_driver_against_the_model():
    bus, clock = board()
    driver = Hts221(bus, 0x5F, clock, 12.5)
    driver.probe()
    driver.configure()
    got = []
    for _ in range(30):
        got += _records(driver.poll())
        time.sleep(0.02)
    assert not got  # less than the batch of one second
    got = _records(driver.flush())
    assert got and got[-1]["relative_humidity_pct"] == pytest.approx(47.5, abs=0.01)
    assert got[-1]["temperature_c"] == pytest.approx(21.3, abs=0.01)
    assert [(r["humidity_raw"], r["temperature_raw"]) for r in got] == bus.models["hts221"].served


class SteppedClock(Clock):
    """Emulation time that moves only when the test says so [ns]."""

    def __init__(self):
        super().__init__()
        self.now_ns = 1_000_000_000_000

    def monotonic_ns(self) -> int:
        return self.now_ns

    def realtime_ns(self) -> int:
        return self.now_ns + 1_700_000_000_000_000_000


class LateClockRead:
    """An SMBus whose reads of one register are followed by a scheduling gap before the caller
    reads the clock (the thread descheduled between FIFO_SRC and ``monotonic_ns``)."""

    def __init__(self, bus, clock, register, gaps_ns):
        self.bus, self.clock, self.register, self.gaps_ns = bus, clock, register, iter(gaps_ns)

    def read_byte_data(self, address, register):
        value = self.bus.read_byte_data(address, register)
        if register == self.register:
            self.clock.now_ns += next(self.gaps_ns)
        return value

    def __getattr__(self, name):
        return getattr(self.bus, name)


def stepped_board():
    clock = SteppedClock()
    t = np.array([0.0, 1000.0])
    signals = TimeSeries({"time_s": t, "accel_x_mps2": np.full(2, 1.25), "accel_z_mps2": np.full(2, 9.80665),
                          "gyro_z_radps": np.full(2, 0.05), "pressure_pa": np.full(2, 95_123.0)})
    return sensor_board(signals, clock, clock.now_ns), clock


@pytest.mark.parametrize("rate_error", [0.0, 0.03, -0.03])
def test_lsm9ds1_fifo_delivers_every_sample_at_952_hz(rate_error):
    """Late polls (up to a full FIFO) and late clock reads after FIFO_SRC, on a sensor whose
    oscillator is off by ``rate_error``: every sample delivered, stamps strictly increasing and
    within the read window of the sample's true time."""
    bus, clock = stepped_board()
    rng = np.random.default_rng(9)
    polls = 600
    read_gaps_ns = rng.choice([0, 0, 0, 50_000, 3_000_000, 8_000_000], size=polls)
    late = LateClockRead(bus, clock, lsm.FIFO_SRC, read_gaps_ns)
    driver = Lsm9ds1(late, 0x6B, clock, 952.0, accel_range_g=4, gyro_range_dps=245)
    driver.probe()
    driver.configure()
    model = bus.models["lsm9ds1"]
    model.odr_hz = 952.0 * (1.0 + rate_error)
    samples = []
    for gap_ns in rng.uniform(1e6, 15e6, size=polls).astype(np.int64):
        clock.now_ns += int(gap_ns)
        samples += [contract.unpack(contract.IMU, p) for topic, p, _, _ in driver.poll() if topic is contract.IMU]
    samples.extend(contract.unpack(contract.IMU, payload) for topic, payload, _, _ in driver.flush()
                   if topic is contract.IMU)
    samples = np.concatenate(samples)
    assert model.overwritten == 0 and driver.overruns == 0
    assert len(samples) == len(model.served) == model.produced >= 0.95 * polls * 8e-3 * 952
    scale = lsm.accel_scale_mps2_per_lsb(4)
    assert scale == pytest.approx(0.122e-3 * 9.80665)
    assert np.all(samples["accel_raw"][:, 0] == round(1.25 / scale))
    assert np.all(samples["accel_raw"][:, 2] == round(9.80665 / scale))
    assert np.all(samples["gyro_raw"][:, 2] == round(0.05 / lsm.gyro_scale_radps_per_lsb(245)))
    stamps = samples["t_mono_ns"].astype(np.int64)
    period_ns = 1e9 / 952.0
    assert np.all(np.diff(stamps) > 0)
    assert np.diff(stamps).min() >= 0.75 * period_ns - 1 and np.diff(stamps).max() <= 1.25 * period_ns + 1
    true_ns = model.on_since_ns + np.arange(1, len(stamps) + 1) * 1e9 / model.odr_hz
    error_ms = (stamps - true_ns) * 1e-6
    print(f"rate error {rate_error:+.0%}: stamp - true time {error_ms.min():.2f} .. {error_ms.max():.2f} ms")
    assert np.all(np.abs(stamps - true_ns)[len(stamps) // 10:] <= period_ns + read_gaps_ns.max())


def test_lsm9ds1_in_real_time_counts_what_a_busy_machine_loses():
    """Real threads and a real clock: whatever the scheduler does, every sample the sensor gave
    is delivered once, stamps strictly increase, and an overflow (if any) is counted."""
    bus, clock = board()
    driver = Lsm9ds1(bus, 0x6B, clock, 952.0)
    driver.probe()
    driver.configure()
    samples = []
    for _ in range(60):
        samples += [contract.unpack(contract.IMU, p) for topic, p, _, _ in driver.poll() if topic is contract.IMU]
        time.sleep(0.008)
    samples.extend(contract.unpack(contract.IMU, payload) for topic, payload, _, _ in driver.flush()
                   if topic is contract.IMU)
    samples = np.concatenate(samples)
    model = bus.models["lsm9ds1"]
    assert len(samples) == len(model.served) > 0
    assert (driver.overruns > 0) == (model.overwritten > 0)
    assert np.all(np.diff(samples["t_mono_ns"].astype(np.int64)) > 0)


def test_sample_clock_is_exact_when_reads_are_on_time():
    from haulprofile.logger.sources.i2c.sample_clock import FifoSampleClock
    period = 1_000_000
    sample_clock = FifoSampleClock(period)
    out = []
    taken = 0
    for n in (5, 8, 3, 8, 8):  # read half a period after the newest sample was taken
        taken += n
        out += sample_clock.stamps(n, taken * period + period // 2, taken * period + period // 2)
    assert out == [k * period for k in range(1, taken + 1)]
    assert sample_clock.corrections == 0
    # an overrun re-anchors on the read window but never goes back in time
    assert sample_clock.stamps(2, 0, 0, overrun=True) == [(taken + 1) * period, (taken + 2) * period]


def test_lps25hb_fifo_stamps_with_late_reads():
    bus, clock = stepped_board()
    late = LateClockRead(bus, clock, 0x2F, [30_000_000, 0, 60_000_000] * 20)
    driver = Lps25hb(late, 0x5C, clock, 25.0)
    driver.configure()
    records = []
    for _ in range(60):
        clock.now_ns += 250_000_000
        records += _records(driver.poll())
    stamps = np.array([r["t_mono_ns"] for r in records])
    model = bus.models["lps25hb"]
    assert len(records) == len(model.served) >= model.produced - 2 and model.overwritten == 0
    assert np.all(np.diff(stamps) > 0)


def test_lsm9ds1_overrun_is_counted_when_polled_too_late():
    bus, clock = board()
    driver = Lsm9ds1(bus, 0x6B, clock, 952.0, batch_s=0.0)
    driver.configure()
    time.sleep(0.1)
    out = driver.poll()
    assert out[0][3] == 32 and len(out[0][1]) == 32 * contract.IMU_SAMPLE_DTYPE.itemsize
    assert driver.overruns == 1 and bus.models["lsm9ds1"].overwritten > 0


class LateWakeClock(SteppedClock):
    """Stepped time in which every sleep of the bus thread ends ``late_ns`` after it was due (a
    thread the scheduler or the interpreter lock keeps waiting); stops the source after ``sleeps``."""

    def __init__(self, late_ns: int, sleeps: int):
        super().__init__()
        self.late_ns, self.sleeps_left, self.source = late_ns, sleeps, None

    def thread_sleep(self, emulated_s: float) -> None:
        self.now_ns += int(emulated_s * 1e9) + self.late_ns
        self.sleeps_left -= 1
        if self.sleeps_left == 0:
            self.source.stop_thread()


class HandOverLoop:
    """The event loop's side of the bus thread's hand-over, collecting what it is given."""

    def __init__(self):
        self.results = []

    def call_soon_threadsafe(self, callback, results) -> None:
        self.results += results


def _bus_thread_with_late_wakeups(late_ns: int):
    """The I2C bus thread's own schedule (all four sensors, IMU at 952 Hz) on stepped time."""
    bus, _ = stepped_board()
    clock = LateWakeClock(late_ns, sleeps=600)
    for model in bus.models.values():
        model.clock = clock
    bus.clock = clock
    drivers = [Lps25hb(bus, 0x5C, clock, 25.0), Hts221(bus, 0x5F, clock, 12.5),
               Lsm9ds1(bus, 0x6B, clock, 952.0), Lsm9ds1Magnetometer(bus, 0x1E, clock, 10.0)]
    source = I2cBusSource(None, clock, drivers)
    clock.source, source._loop = source, HandOverLoop()
    source._bus_thread()
    return bus.models["lsm9ds1"], source._loop.results


@pytest.mark.parametrize("late_ms", [0, 10, 20, 24])
def test_bus_thread_reads_the_imu_fifo_before_it_fills_when_wakeups_come_late(late_ms):
    """The IMU FIFO holds 32 samples (33.6 ms at 952 Hz); the bus thread reads it early enough
    that a wake-up up to 24 ms late loses nothing (read at half full, 20 ms late lost samples)."""
    model, results = _bus_thread_with_late_wakeups(late_ms * 1_000_000)
    assert model.produced > 4000 and model.overwritten == 0
    assert sum(overruns for name, _, overruns, _, _ in results if name == "lsm9ds1") == 0
    imu_records = sum(records for name, out, *_ in results if name == "lsm9ds1"
                      for topic, *_, records in out if topic is contract.IMU)
    assert imu_records == len(model.served) == model.produced - len(model.fifo)


def test_bus_thread_counts_the_loss_when_wakeups_come_later_than_the_fifo_holds():
    model, results = _bus_thread_with_late_wakeups(34_000_000)
    lost = sum(overruns for name, _, overruns, _, _ in results if name == "lsm9ds1")
    assert model.overwritten > 0 and lost > 0


def test_lsm9ds1_reads_its_die_temperature_once_a_second():
    """OUT_TEMP (two's complement, 16 LSB/degC, 0 at 25 degC) read beside the FIFO once a second,
    below and above 25 degC, and every FIFO sample still delivered."""
    clock = SteppedClock()
    t = np.arange(0.0, 60.0, 0.001)  # the emulator holds each value until the next
    signals = TimeSeries({"time_s": t, "accel_z_mps2": np.full(t.size, 9.80665), "imu_temperature_c": 24.0 + t})
    bus = sensor_board(signals, clock, clock.now_ns)
    driver = Lsm9ds1(bus, 0x6B, clock, 952.0)
    driver.probe()
    driver.configure()
    model = bus.models["lsm9ds1"]
    out = []
    for _ in range(3000):  # 3000 polls 10 ms apart: 30 s
        clock.now_ns += 10_000_000
        out += driver.poll()
    out += driver.flush()
    temperature = [(t_ns, c, raw) for topic, payload, *_ in out if topic is contract.IMU_TEMPERATURE
                   for t_ns, c, raw, _ in contract.unpack(contract.IMU_TEMPERATURE, payload).tolist()]
    imu = sum(count for topic, *_, count in out if topic is contract.IMU)
    assert imu == len(model.served) == model.produced - len(model.fifo)
    assert len(temperature) == 30
    stamps = np.array([t_ns for t_ns, _, _ in temperature])
    assert np.allclose(np.diff(stamps), 1e9, atol=1e7)
    expected = 24.0 + (stamps - 1_000_000_000_000) / 1e9  # 1 K/s from the board's start
    celsius = np.array([c for _, c, _ in temperature])
    raw = np.array([r for _, _, r in temperature])
    assert np.array_equal(celsius, 25.0 + raw / 16.0) and raw[0] < 0 < raw[-1]
    assert np.all(np.abs(celsius - expected) <= 1 / 32 + 0.012)  # half a count, a poll's 10 ms, a sample
    metadata = driver.channel_metadata()[contract.IMU_TEMPERATURE.name]
    assert float(metadata["temperature_lsb_per_c"]) == 16.0 and float(metadata["temperature_zero_c"]) == 25.0


def test_magnetometer_and_metadata():
    bus, clock = board()
    mag = Lsm9ds1Magnetometer(bus, 0x1E, clock, 10.0, batch_s=0.0)
    mag.probe()
    mag.configure()
    time.sleep(0.15)
    record, = _records(mag.poll())
    assert record["magnetic_field_t"][0] == pytest.approx(20e-6, abs=0.14e-7)
    metadata = Lsm9ds1(bus, 0x6B, clock).channel_metadata()["/imu"]
    assert float(metadata["gyro_scale_radps_per_lsb"]) == pytest.approx(np.radians(8.75e-3))


def test_who_am_i_mismatch_and_missing_device():
    bus, clock = board(missing=("hts221",))
    with pytest.raises(SensorMissing, match="does not answer"):
        Hts221(bus, 0x5F, clock).probe()
    with pytest.raises(SensorMissing, match="WHO_AM_I 0xbd"):
        Hts221(bus, 0x5C, clock).probe()
