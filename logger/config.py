"""The daemon's one TOML file, read into dataclasses; a bad key is a one-line error naming it.

Every section and key, with its default, is documented in ``docs/logger.md`` and shown in
``logger/logger.example.toml``.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
import typing
from dataclasses import dataclass, field
from pathlib import Path

from haulprofile.contract import obd
from haulprofile.contract.input_files import read_small
from haulprofile.contract.privacy import zones_from_tables
from haulprofile.contract.toml_tables import check_typed, table_kwargs


class ConfigError(Exception):
    """A problem with the configuration file, said in one line naming the key."""


@dataclass
class LoggerSection:
    directory: str = "/var/lib/haulprofile/logs"
    prefix: str = "haulprofile"
    queue_size: int = 4096
    time_scale: float = 1.0
    """Emulation only: emulated seconds per real second (all periods are in emulated time)."""
    watchdog: bool = True


@dataclass
class StorageSection:
    rotate_size_mb: float = 256.0
    rotate_interval_s: float = 3600.0
    chunk_size_kb: float = 256.0
    chunk_interval_s: float = 1.0
    compression: str = "zstd"
    fsync: bool = True
    min_free_mb: float = 512.0
    on_low_space: str = "delete_oldest"


@dataclass
class ObdSection:
    enabled: bool = True
    rate_hz: float = 30.0
    pids: list[int] = field(default_factory=lambda: list(obd.DEFAULT_POLL_PIDS))
    pids_per_request: int = 1
    addressing: str = "11bit"
    timeout_s: float = 0.1
    failed_rounds_before_probe: int = 3
    probe_interval_s: float = 2.0


@dataclass
class J1939Section:
    enabled: bool = True
    source_address: int = 0xF9
    request_pgns: list[int] = field(default_factory=lambda: [65251, 65258])
    request_destination: int = 0xFF
    request_interval_s: float = 10.0
    answer_rts: bool = True


@dataclass
class CanSection:
    enabled: bool = True
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: int = 250000
    listen_only: bool = True
    """Transmit nothing (the default): OBD-II polling and J1939 requests need ``listen_only = false``."""
    receive_interval_s: float = 0.02
    batch_interval_s: float = 0.2
    more_channels: list[str] = field(default_factory=list)
    """Further buses of the same interface and bitrate (a truck's second J1939 bus), listened to
    only, their frames logged with ``channel`` 1, 2, … in the record (``channel`` above is 0)."""
    obd: ObdSection = field(default_factory=ObdSection)
    j1939: J1939Section = field(default_factory=J1939Section)


@dataclass
class Lps25hbSection:
    enabled: bool = True
    address: int = 0x5C
    odr_hz: float = 25.0


@dataclass
class Hts221Section:
    enabled: bool = True
    address: int = 0x5F
    odr_hz: float = 12.5


@dataclass
class Lsm9ds1Section:
    enabled: bool = True
    address_ag: int = 0x6B
    address_m: int = 0x1E
    odr_hz: float = 952.0
    accel_range_g: int = 4
    gyro_range_dps: int = 245
    magnetometer: bool = True
    mag_odr_hz: float = 10.0


@dataclass
class I2cSection:
    enabled: bool = True
    bus: int = 1
    lps25hb: Lps25hbSection = field(default_factory=Lps25hbSection)
    hts221: Hts221Section = field(default_factory=Hts221Section)
    lsm9ds1: Lsm9ds1Section = field(default_factory=Lsm9ds1Section)


@dataclass
class GpsSection:
    enabled: bool = True
    port: str = "/dev/ttyACM0"
    baudrate: int = 9600
    configure_rate: bool = False
    rate_hz: float = 10.0
    request_accuracy: bool = True
    """Send UBX-CFG-MSG for GST at start: without it a u-blox states no accuracy and the gradient
    cannot weigh GPS altitude."""


@dataclass
class PrivacySection:
    """Privacy zones and coarsening, applied before anything reaches the disk (docs/privacy.md)."""

    zones: list[dict] = field(default_factory=list)
    """``[[privacy.zones]]``: circles (``lat``, ``lon``, ``radius_m``) or ``polygon = [[lat, lon], …]``."""
    position_grid_m: float = 0.0
    """> 0: every position written is the centre of its cell of this size [m] (0: full precision)."""
    time_resolution_s: float = 0.0
    """> 0: wall-clock and GPS time are kept only to this resolution [s], e.g. 60 (0: full)."""
    drop_can_pgns: list[int] = field(default_factory=lambda: [65267, 65254])
    """J1939 PGNs not logged while any privacy setting is in use: Vehicle Position (65267) and
    Time/Date (65254), a telematics unit's broadcast of what the zones and coarsening withhold."""

    @property
    def active(self) -> bool:
        return bool(self.zones) or self.position_grid_m > 0 or self.time_resolution_s > 0


@dataclass
class EncryptionSection:
    """Encryption at rest (age): each closed log becomes ``.mcap.age`` for these public keys."""

    recipients: list[str] = field(default_factory=list)
    """age (``age1…``) or SSH public keys of the fleet; empty: logs stay plaintext."""


@dataclass
class EmulationSection:
    """Run the device emulators inside the daemon (tests, demo, crash drills); never on a truck."""

    enabled: bool = False
    signals: str = "synthetic"
    """``synthetic`` or the path of an ``.npz`` of time series (``time_s`` plus signal columns)."""
    can_channel: str = "haulprofile-emulated"
    j1939_broadcast: bool = True


@dataclass
class Config:
    logger: LoggerSection = field(default_factory=LoggerSection)
    storage: StorageSection = field(default_factory=StorageSection)
    can: CanSection = field(default_factory=CanSection)
    i2c: I2cSection = field(default_factory=I2cSection)
    gps: GpsSection = field(default_factory=GpsSection)
    privacy: PrivacySection = field(default_factory=PrivacySection)
    encryption: EncryptionSection = field(default_factory=EncryptionSection)
    emulation: EmulationSection = field(default_factory=EmulationSection)


_CHOICES = {
    "storage.compression": ("zstd", "lz4", "none"),
    "storage.on_low_space": ("delete_oldest", "pause"),
    "can.obd.addressing": ("11bit", "29bit"),
}
_POSITIVE = {"logger.queue_size", "logger.time_scale", "storage.rotate_size_mb", "storage.rotate_interval_s",
             "storage.chunk_size_kb", "storage.chunk_interval_s", "can.batch_interval_s", "can.obd.rate_hz",
             "can.obd.timeout_s", "can.obd.probe_interval_s", "can.obd.failed_rounds_before_probe",
             "can.j1939.request_interval_s", "i2c.lps25hb.odr_hz", "i2c.hts221.odr_hz", "i2c.lsm9ds1.odr_hz",
             "i2c.lsm9ds1.mag_odr_hz", "gps.baudrate", "gps.rate_hz", "can.bitrate"}
_NON_NEGATIVE = {"storage.min_free_mb"}
I2C_ADDRESSES = range(0x08, 0x78)
"""7-bit I2C addresses a device may have (0x00-0x07 and 0x78-0x7F are reserved)."""


def _build(cls, data: dict, prefix: str):
    """``cls`` from its table, nested sections by their own tables (`toml_tables.table_kwargs`)."""
    hints = typing.get_type_hints(cls)

    def check(_where, name, value, _annotation):
        key = f"{prefix}.{name}" if prefix else name
        if dataclasses.is_dataclass(hints[name]):
            if not isinstance(value, dict):
                raise ConfigError(f"config: {key} must be a table [{key}]")
            return _build(hints[name], value, key)
        value = check_typed(f"config: {key}", value, hints[name], ConfigError)
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"config: {key} must be a finite number, got {value!r}")
        if key in _CHOICES and value not in _CHOICES[key]:
            raise ConfigError(f"config: {key} must be one of {', '.join(_CHOICES[key])}, got {value!r}")
        if key in _POSITIVE and not value > 0:
            raise ConfigError(f"config: {key} must be > 0, got {value!r}")
        if key in _NON_NEGATIVE and not value >= 0:
            raise ConfigError(f"config: {key} must be 0 or more, got {value!r}")
        return value

    return cls(**table_kwargs(cls, data, "config", check, ConfigError,
                              key_name=lambda name: f"{prefix}.{name}" if prefix else name))


MAX_RECEIVE_INTERVAL_S = 0.05
"""Longest CAN receive cadence: an ISO-TP flow control must follow a first frame within N_Bs
(75 ms in ISO 15765-4), and frames waiting in the socket buffer must not overflow it [s]."""


PREFIX = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
"""A log file name's prefix: a plain name, no folder (``a/b``, ``../escape``) and no hidden file."""


def _check(config: Config) -> None:
    if not PREFIX.fullmatch(config.logger.prefix):
        raise ConfigError(f"config: logger.prefix {config.logger.prefix!r} must be a plain name of letters, digits, "
                          "'.', '_' or '-' (no '/', not starting with '.'), e.g. \"truck07\"")
    if not 0.0 <= config.can.receive_interval_s <= MAX_RECEIVE_INTERVAL_S:
        raise ConfigError(f"config: can.receive_interval_s must be 0 to {MAX_RECEIVE_INTERVAL_S:g} s "
                          f"(flow control within ISO 15765-4's N_Bs), got {config.can.receive_interval_s!r}")
    channels = [config.can.channel, *config.can.more_channels]
    if len(set(channels)) != len(channels) or len(channels) > 255:
        raise ConfigError(f"config: can.more_channels must name up to 254 buses other than can.channel, "
                          f"each once, got {config.can.more_channels!r}")
    if not 1 <= config.can.obd.pids_per_request <= 6:
        raise ConfigError("config: can.obd.pids_per_request must be 1 to 6 (SAE J1979)")
    for pid in config.can.obd.pids:
        if pid not in obd.PIDS:
            raise ConfigError(f"config: can.obd.pids has {pid:#04x}, not one of the known PIDs "
                              f"{', '.join(f'{p:#04x}' for p in obd.PIDS)}")
    for key, value in (("can.j1939.source_address", config.can.j1939.source_address),
                       ("can.j1939.request_destination", config.can.j1939.request_destination)):
        if not 0 <= value <= 0xFF:
            raise ConfigError(f"config: {key} must be 0 to 255, got {value}")
    for pgn in config.can.j1939.request_pgns:
        if not 0 <= pgn <= 0x3FFFF:
            raise ConfigError(f"config: can.j1939.request_pgns has {pgn}, not an 18-bit PGN")
    if config.i2c.lsm9ds1.odr_hz not in (14.9, 59.5, 119.0, 238.0, 476.0, 952.0):
        raise ConfigError("config: i2c.lsm9ds1.odr_hz must be one of 14.9, 59.5, 119, 238, 476, 952")
    if config.i2c.lsm9ds1.accel_range_g not in (2, 4, 8, 16):
        raise ConfigError("config: i2c.lsm9ds1.accel_range_g must be 2, 4, 8 or 16")
    if config.i2c.lsm9ds1.gyro_range_dps not in (245, 500, 2000):
        raise ConfigError("config: i2c.lsm9ds1.gyro_range_dps must be 245, 500 or 2000")
    if config.i2c.lps25hb.odr_hz not in (1.0, 7.0, 12.5, 25.0):
        raise ConfigError("config: i2c.lps25hb.odr_hz must be 1, 7, 12.5 or 25")
    if config.i2c.lsm9ds1.mag_odr_hz not in (0.625, 1.25, 2.5, 5.0, 10.0, 20.0, 40.0, 80.0):
        raise ConfigError("config: i2c.lsm9ds1.mag_odr_hz must be one of 0.625, 1.25, 2.5, 5, 10, 20, 40, 80")
    if config.i2c.hts221.odr_hz not in (1.0, 7.0, 12.5):
        raise ConfigError("config: i2c.hts221.odr_hz must be 1, 7 or 12.5")
    for key, address in (("i2c.lps25hb.address", config.i2c.lps25hb.address),
                         ("i2c.hts221.address", config.i2c.hts221.address),
                         ("i2c.lsm9ds1.address_ag", config.i2c.lsm9ds1.address_ag),
                         ("i2c.lsm9ds1.address_m", config.i2c.lsm9ds1.address_m)):
        if address not in I2C_ADDRESSES:
            raise ConfigError(f"config: {key} must be a 7-bit I2C address 0x08 to 0x77, got {address:#x}")
    try:
        zones_from_tables(config.privacy.zones, "privacy.zones")
    except ValueError as exc:
        raise ConfigError(f"config: {exc}") from None
    for key in ("position_grid_m", "time_resolution_s"):
        if not getattr(config.privacy, key) >= 0:
            raise ConfigError(f"config: privacy.{key} must be >= 0 (0: off), got {getattr(config.privacy, key)!r}")
    if config.encryption.recipients:
        from .encryption import EncryptionUnavailable, parse_recipients
        try:
            parse_recipients(config.encryption.recipients)
        except EncryptionUnavailable as exc:
            raise ConfigError(f"config: {exc}") from None
    if config.logger.time_scale != 1.0 and not config.emulation.enabled:
        raise ConfigError("config: logger.time_scale other than 1 needs [emulation] enabled = true")


def from_dict(data: dict) -> Config:
    config = _build(Config, data, "")
    _check(config)
    return config


def example_path() -> Path:
    """The example configuration shipped with the package."""
    return Path(__file__).with_name("logger.example.toml")


def load(path: str | Path) -> Config:
    """Read and check a configuration file; raises `ConfigError` with a one-line message."""
    path = Path(path)
    raw = read_small(path, "config:", ConfigError)
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise ConfigError(f"config: {path} is saved as UTF-16; save it as UTF-8 (TOML is UTF-8)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"config: {path} is not UTF-8 text (invalid byte at offset {exc.start}); "
                          f"TOML is UTF-8") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config: {path} is not valid TOML: {exc}") from None
    if not data:
        raise ConfigError(f"config: {path} sets nothing; start from {example_path()} and set at least "
                          f"[logger] directory")
    return from_dict(data)
