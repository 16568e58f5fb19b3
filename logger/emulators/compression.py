"""Time-compressed emulation (``analyze demo``, the end-to-end tests): how fast, and at which rates.

The daemon and the emulators share one clock running ``time_scale`` times faster than real time;
what a sensor FIFO or an ECU tolerates is real time, so the rates here keep each of them at least
some tens of milliseconds of real time from losing data on a shared 2-core machine.
"""

from __future__ import annotations

from ..config import MAX_RECEIVE_INTERVAL_S, Config

DEMO_TIME_SCALE = 40.0
"""Emulated seconds per real second of `rig.record_streams` and ``analyze demo``: the 38-minute
demo drive in under a minute. `compressed_config` keeps every sensor FIFO at least 54 ms of real
time deep there (107 ms at 20x), and the emulated ECU keeps up on a shared 2-core machine."""

COMPRESSED_OBD_RATE_HZ = 5.0
"""OBD-II requests per emulated second in time-compressed runs (30 on the truck): the J1939
broadcast carries the same signals, and each request costs the emulated ECU and the logger a
thread wake-up each [Hz]."""
OBD_REAL_TIMEOUT_S = 0.05
"""OBD-II answer timeout in real seconds in time-compressed runs: the emulated ECU is a thread that
may wait this long for the interpreter on a busy machine, which at 40x is 2 s of the drive's time
(a real ECU answers within ISO 15765-4's P2 of 50 ms) [s]."""


def compressed_config(time_scale: float, gps_rate_hz: float | None = None) -> Config:
    """Sensor rates and CAN timing that polling keeps up with at ``time_scale`` on a busy machine.

    Sensors read through a FIFO (LPS25HB, LSM9DS1) tolerate a poll as late as their 32-slot FIFO
    takes to fill, so they run at their slowest legal rates (LPS25HB 7 Hz: 4.6 s of the drive,
    114 ms of real time at 40x; LSM9DS1 14.9 Hz: 54 ms); the HTS221 and the magnetometer have no
    FIFO and run at 1 and 1.25 Hz. The CAN reader wakes at its longest legal cadence, OBD-II is
    polled at `COMPRESSED_OBD_RATE_HZ` with `OBD_REAL_TIMEOUT_S` of real time to answer, and the
    GPS sends at ``gps_rate_hz`` (the rate of the fixes it is fed, 1 to 10 Hz: more epochs would
    repeat the same fix).
    """
    config = Config()
    if time_scale > 4.0:
        config.i2c.lsm9ds1.odr_hz = 14.9
        config.i2c.lsm9ds1.mag_odr_hz = 1.25
        config.i2c.hts221.odr_hz = 1.0
        config.i2c.lps25hb.odr_hz = 7.0
        config.can.j1939.request_interval_s = 30.0
        config.can.receive_interval_s = MAX_RECEIVE_INTERVAL_S
        config.can.obd.rate_hz = COMPRESSED_OBD_RATE_HZ
        config.can.obd.timeout_s = max(config.can.obd.timeout_s, OBD_REAL_TIMEOUT_S * time_scale)
        if gps_rate_hz is not None:
            config.gps.rate_hz = min(max(gps_rate_hz, 1.0), 10.0)
    return config
