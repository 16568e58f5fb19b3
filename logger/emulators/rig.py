"""All emulators behind the daemon's device seam, and `record_drive`: the real daemon on a drive.

`EmulatedDevices` starts an ECU on a python-can ``virtual`` bus, the I2C sensor board and a GPS
on a pty, all fed by one `TimeSeries` on one `Clock`; the daemon is the unchanged production
daemon with this seam instead of the hardware one.
"""

from __future__ import annotations

import asyncio
import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from ..clock import Clock
from ..config import Config
from ..devices import Devices
from .compression import DEMO_TIME_SCALE, compressed_config
from .ecu import EcuEmulator
from .gps import GpsEmulator
from .sensors import sensor_board
from .signals import TimeSeries, stream_rate_hz, synthetic_drive


class EmulatedDevices(Devices):
    """Device seam handing out emulators; ``start()`` before the daemon runs, ``close()`` after."""

    def __init__(self, signals: TimeSeries, clock: Clock, missing_sensors: tuple[str, ...] = (),
                 answer_obd: bool = True, broadcast: bool = True, ecu_options: dict | None = None,
                 gps_link: str | Path | None = None):
        """``gps_link``: a stable path the GPS pty is reached through (see `GpsEmulator`)."""
        self.signals = signals
        self.gps_link = gps_link
        self.clock = clock
        self.missing_sensors = missing_sensors
        self.answer_obd = answer_obd
        self.broadcast = broadcast
        self.ecu_options = ecu_options or {}
        self.ecu: EcuEmulator | None = None
        self.board = None
        self.gps: GpsEmulator | None = None
        self.t0_ns = 0
        self._ecu_bus = None
        self._channel = "haulprofile-emulated"

    def start(self, config: Config) -> "EmulatedDevices":
        import can
        self._channel = config.emulation.can_channel
        self.t0_ns = self.clock.monotonic_ns()
        i2c = config.i2c
        self.board = sensor_board(self.signals, self.clock, self.t0_ns, i2c.lps25hb.address, i2c.hts221.address,
                                  i2c.lsm9ds1.address_ag, i2c.lsm9ds1.address_m, self.missing_sensors)
        self.gps = GpsEmulator(self.signals, self.clock, self.t0_ns, config.gps.rate_hz, link=self.gps_link)
        self._ecu_bus = can.Bus(interface="virtual", channel=self._channel, receive_own_messages=False)
        self.ecu = EcuEmulator(self._ecu_bus, self.signals, self.clock, answer_obd=self.answer_obd,
                               broadcast=self.broadcast and config.emulation.j1939_broadcast, **self.ecu_options)
        return self

    def run_emulators(self) -> None:
        """Start the drive once the daemon opened its ends: signal time 0 is now.

        A daemon slow to get ready (a loaded machine, a high time scale) would otherwise start
        logging a truck that is already moving; before time 0 every device reports the drive's
        first state, a truck standing still.
        """
        self.t0_ns = self.clock.monotonic_ns()
        for model in self.board.models.values():
            model.t0_ns = self.t0_ns
        self.gps.t0_ns = self.t0_ns
        self.ecu.start(self.t0_ns)
        self.gps.start()

    def stop_emulators(self) -> None:
        """Stop producing (ECU and GPS threads); the daemon can then log what is in flight."""
        if self.ecu is not None:
            self.ecu.stop()
        if self.gps is not None:
            self.gps.stop()

    def can_bus(self, config: Config, channel: str | None = None):
        """The ECU's virtual bus; another channel (``can.more_channels``) is a virtual bus of that name."""
        import can
        name = self._channel if channel in (None, config.can.channel) else channel
        return can.Bus(interface="virtual", channel=name, receive_own_messages=False)

    def smbus(self, config: Config):
        return self.board

    def gps_port(self, config: Config) -> str:
        return self.gps.port

    def close(self) -> None:
        if self.ecu is not None:
            self.ecu.stop()
            self._ecu_bus.shutdown()
        if self.gps is not None:
            self.gps.close()


def load_signals(spec: str) -> TimeSeries:
    """``synthetic`` or an ``.npz`` of arrays with ``time_s``."""
    if spec == "synthetic":
        return TimeSeries(synthetic_drive())
    with np.load(spec) as data:
        return TimeSeries({k: data[k] for k in data.files})


PROGRESS_EVERY_S = 10.0
"""How often `run_daemon_for` reports progress, in real seconds [s]."""


@dataclass(frozen=True)
class Progress:
    """How far a logged drive got: ``driven_s`` of ``duration_s`` emulated seconds [s], and the
    CAN frames the daemon's CAN sources took so far."""

    driven_s: float
    duration_s: float
    can_frames: int


def progress_of(daemon, devices: EmulatedDevices, duration_s: float) -> Progress:
    """The drive's progress now: emulated time since the emulators started, CAN frames logged."""
    driven_s = (daemon.clock.monotonic_ns() - devices.t0_ns) * 1e-9
    frames = sum(source.stats.records for source in daemon.sources if source.name.startswith("can"))
    return Progress(min(max(driven_s, 0.0), duration_s), duration_s, frames)


async def run_daemon_for(daemon, devices: EmulatedDevices, duration_s: float, progress=None,
                         progress_every_s: float = PROGRESS_EVERY_S) -> int:
    """Run ``daemon`` with the emulators for ``duration_s`` emulated seconds, then stop it.

    ``progress``: called with a `Progress` every ``progress_every_s`` real seconds while it runs
    (the caller prints it; the rig does not)."""
    task = asyncio.create_task(daemon.run())
    await daemon.ready.wait()
    devices.run_emulators()
    if duration_s == float("inf"):
        await asyncio.shield(task)
    else:
        loop = asyncio.get_running_loop()
        end = loop.time() + daemon.clock.real_seconds(duration_s)
        while (left := end - loop.time()) > 0:
            wait_s = left if progress is None else min(left, progress_every_s)
            done, _ = await asyncio.wait({task}, timeout=wait_s)
            if done:
                break
            if progress is not None and end - loop.time() > 0:
                progress(progress_of(daemon, devices, duration_s))
    await asyncio.get_running_loop().run_in_executor(None, devices.stop_emulators)
    await asyncio.sleep(0.3)
    daemon.stop()
    code = await task
    devices.close()
    return code


def emulation_config(out_dir: str | Path, time_scale: float = 1.0, base: Config | None = None,
                     transmit: bool = True) -> Config:
    """A configuration for logging from the emulators into ``out_dir``. On this bench the only
    ECU is the emulator, so the logger polls it (``transmit=False``: listen-only, as on a truck
    by default)."""
    config = copy.deepcopy(base) if base is not None else Config()
    config.can.listen_only = not transmit
    config.logger.directory = str(out_dir)
    config.logger.time_scale = time_scale
    config.emulation.enabled = True
    config.can.interface = "virtual"
    config.can.channel = config.emulation.can_channel
    config.storage.min_free_mb = 1.0
    return config


def record_drive(signals: Mapping[str, np.ndarray], out_dir: str | Path, duration_s: float | None = None,
                 time_scale: float = 1.0, config: Config | None = None, return_rig: bool = False,
                 progress=None, progress_every_s: float = PROGRESS_EVERY_S):
    """Log a drive through the real daemon and the emulators; returns the path of the MCAP log.

    ``signals``: column name -> array, with ``time_s`` [s] and any of ``speed_mps``,
    ``engine_speed_rpm``, ``actual_engine_torque_pct``, ``driver_demand_torque_pct``,
    ``engine_reference_torque_nm``, ``pressure_pa``, ``temperature_c``, ``relative_humidity_pct``,
    ``accel_x_mps2``…, ``gyro_x_radps``…, ``latitude_deg``, ``longitude_deg``, ``altitude_m``,
    ``h_acc_m``, ``v_acc_m``. ``duration_s`` defaults to the length of the series; ``time_scale``
    emulated seconds pass per real second. With ``return_rig`` also returns (daemon, devices).
    ``progress``: called with a `Progress` every ``progress_every_s`` real seconds.
    """
    from ..daemon import Daemon
    series = TimeSeries(signals)
    config = emulation_config(out_dir, time_scale, config)
    config.storage.rotate_size_mb = max(config.storage.rotate_size_mb, 4096.0)
    config.storage.rotate_interval_s = max(config.storage.rotate_interval_s, 10 * 24 * 3600.0)
    clock = Clock(time_scale)
    devices = EmulatedDevices(series, clock).start(config)
    daemon = Daemon(config, devices, clock)
    duration = series.duration_s if duration_s is None else duration_s
    code = asyncio.run(run_daemon_for(daemon, devices, duration, progress, progress_every_s))
    if code != 0:
        raise RuntimeError(f"logger daemon ended with exit code {code}")
    path = daemon.storage.files_written[0]
    return (path, daemon, devices) if return_rig else path


def record_streams(streams: Mapping[str, object], out_dir: str | Path, duration_s: float | None = None,
                   time_scale: float = DEMO_TIME_SCALE, progress=None) -> Path:
    """Log sensor streams (e.g. ``analysis.virtual_truck.drive(...).sensors``: DataFrames with
    ``time_s`` and scalars) through the real daemon and the emulators; returns the MCAP path.

    ``time_scale`` emulated seconds pass per real second (40: a 38-minute drive in a minute), with
    the rates of `compressed_config` (the GPS at the rate of the ``gps`` stream's fixes);
    ``progress`` as in `record_drive`.
    """
    from .signals import from_streams
    config = compressed_config(time_scale, stream_rate_hz(streams, "gps"))
    return record_drive(from_streams(streams), out_dir, duration_s, time_scale, config, progress=progress)
