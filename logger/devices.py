"""The hardware seam: which bus, SMBus and serial port each source gets.

`Devices` opens the real ones (python-can bus by configured interface, ``smbus2.SMBus``, the
serial port path); `logger.emulators.rig.EmulatedDevices` hands out emulators instead. Hardware
libraries are imported only when a source needs them.
"""

from __future__ import annotations

import logging

from .config import Config
from .sources.base import Source

log = logging.getLogger("haulprofile.logger")


class Devices:
    def can_bus(self, config: Config, channel: str | None = None):
        """The python-can bus of ``channel`` (default ``can.channel``)."""
        import can
        section = config.can
        kwargs = {"interface": section.interface, "channel": channel or section.channel}
        if section.interface != "virtual":
            kwargs["bitrate"] = section.bitrate
        return can.Bus(**kwargs)

    def smbus(self, config: Config):
        import smbus2
        return smbus2.SMBus(config.i2c.bus)

    def gps_port(self, config: Config) -> str:
        return config.gps.port

    def i2c_drivers(self, config: Config, bus, clock) -> list:
        from .sources.i2c.hts221 import Hts221
        from .sources.i2c.lps25hb import Lps25hb
        from .sources.i2c.lsm9ds1 import Lsm9ds1, Lsm9ds1Magnetometer
        i2c = config.i2c
        drivers = []
        if i2c.lps25hb.enabled:
            drivers.append(Lps25hb(bus, i2c.lps25hb.address, clock, i2c.lps25hb.odr_hz))
        if i2c.hts221.enabled:
            drivers.append(Hts221(bus, i2c.hts221.address, clock, i2c.hts221.odr_hz))
        if i2c.lsm9ds1.enabled:
            m = i2c.lsm9ds1
            drivers.append(Lsm9ds1(bus, m.address_ag, clock, m.odr_hz, m.accel_range_g, m.gyro_range_dps))
            if m.magnetometer:
                drivers.append(Lsm9ds1Magnetometer(bus, m.address_m, clock, m.mag_odr_hz))
        return drivers

    def build_sources(self, config: Config, queue, clock, say, privacy=None) -> list[Source]:
        """Open every enabled device; a device that is missing is a warning, the rest logs.
        ``privacy``: the daemon's `..privacy.Privacy` (zones, coarsening) for the GPS and CAN."""
        sources: list[Source] = []
        if config.can.enabled:
            from .sources.can import CanSource, listening_section
            drop = privacy.can_drop_pgns if privacy is not None else frozenset()
            for index, channel in enumerate([config.can.channel, *config.can.more_channels]):
                section = config.can if index == 0 else listening_section(config.can, channel)
                try:
                    bus = self.can_bus(config) if index == 0 else self.can_bus(config, channel)
                    sources.append(CanSource(queue, clock, section, bus, say, drop_pgns=drop, channel_index=index))
                except (OSError, ImportError, ValueError) as exc:
                    say(f"can: cannot open {config.can.interface} {channel}: {exc}; logging without it")
                except Exception as exc:  # python-can raises CanError subclasses and others per backend
                    say(f"can: cannot open {config.can.interface} {channel}: {exc!r}; logging without it")
        if config.i2c.enabled:
            from .sources.i2c.base import I2cBusSource, SensorMissing
            try:
                bus = self.smbus(config)
            except (OSError, ImportError) as exc:
                say(f"i2c: cannot open bus {config.i2c.bus}: {exc}; logging without I2C sensors")
                bus = None
            if bus is not None:
                present = []
                for driver in self.i2c_drivers(config, bus, clock):
                    try:
                        driver.probe()
                    except (SensorMissing, OSError) as exc:
                        say(f"{driver.name}: {exc}; the other sources keep logging")
                        continue
                    present.append(driver)
                if present:
                    sources.append(I2cBusSource(queue, clock, present, say))
        if config.gps.enabled:
            from .sources.gps import GpsSource
            gps = GpsSource(queue, clock, self.gps_port(config), config.gps.baudrate,
                            config.gps.rate_hz if config.gps.configure_rate else None, say, privacy,
                            config.gps.request_accuracy)
            try:
                gps.open()
                sources.append(gps)
            except (OSError, ImportError) as exc:
                say(f"gps: cannot open {config.gps.port}: {exc}; logging without GPS")
            except Exception as exc:  # serial.SerialException
                say(f"gps: cannot open {config.gps.port}: {exc}; logging without GPS")
        return sources

    def channel_metadata(self, sources: list[Source]) -> dict[str, dict[str, str]]:
        metadata: dict[str, dict[str, str]] = {}
        for source in sources:
            for driver in getattr(source, "drivers", ()):
                metadata.update(driver.channel_metadata())
        return metadata

    def last_gps_time_ns(self, sources: list[Source]) -> int | None:
        for source in sources:
            if hasattr(source, "gps_time_now_ns"):
                return source.gps_time_now_ns()
        return None

    def close(self) -> None:
        """Release what the seam itself started (emulators); nothing for real hardware."""
