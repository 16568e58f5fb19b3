"""Scenario files (TOML) of the virtual truck: route, terrain, tunnels, payload, driver, sensors.

Every key is documented in ``docs/virtual-truck.md``. Loading validates the whole file: an unknown
table or key, a missing key, a wrong type or an impossible value is a one-line `ScenarioFileError`
naming the file, table and key.
"""

from __future__ import annotations

import datetime as dt
import tomllib
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path

from ..errors import UserError
from haulprofile.contract.toml_tables import check_number, check_text, is_number, table_kwargs
from ..vehicle import EXAMPLES as VEHICLE_EXAMPLES
from .realism import IDEAL, Realism, realism_level


class ScenarioFileError(UserError):
    pass


@dataclass(frozen=True)
class Section:
    """A stretch of road with one speed limit; ``stop_s`` > 0 means a stop at its end."""

    length_m: float
    speed_kmh: float
    stop_s: float = 0.0


@dataclass(frozen=True)
class Route:
    """Either generated ``section``s or a VECTO ``vdri`` cycle (path relative to the scenario)."""

    section: tuple[Section, ...] = ()
    vdri: str | None = None
    initial_stop_s: float = 10.0
    final_stop_s: float = 30.0


@dataclass(frozen=True)
class Terrain:
    """Road height profile (generated routes) and the hills around the road."""

    base_altitude_m: float = 400.0
    hill_amplitude_m: float = 20.0
    hill_wavelengths_m: tuple[float, ...] = (2500.0, 6000.0)
    cut_fill_m: float = 2.0
    offroad_hill_amplitude_m: float = 40.0
    curviness_deg: float = 50.0
    seed: int = 0


@dataclass(frozen=True)
class Tunnel:
    """The road leaves the terrain: at most ``depth_m`` below it, in the middle of the tunnel."""

    start_m: float
    length_m: float
    depth_m: float = 40.0


@dataclass(frozen=True)
class Payload:
    """Payload at the start and after each stop (in stop order); it changes only at stops."""

    initial_kg: float = 0.0
    after_stop_kg: tuple[float, ...] = ()


@dataclass(frozen=True)
class Driver:
    max_accel_mps2: float = 0.8
    comfort_decel_mps2: float = 1.0
    max_decel_mps2: float = 2.0
    speed_gain_per_s: float = 0.5
    traffic: float = 1.0
    """Scale of the traffic's slow-downs below the speed limit (0 = free road)."""
    downhill_overspeed_kmh: float = 5.0
    """Downhill the truck runs up to this much above the target on engine drag before braking."""


@dataclass(frozen=True)
class Sensors:
    imu_rate_hz: float = 238.0
    gps_rate_hz: float = 1.0
    wheel_speed_noise_kmh: float = 0.05
    engine_speed_noise_rpm: float = 2.0
    engine_torque_noise_pct: float = 0.3
    baro_noise_pa: float = 1.5
    baro_drift_pa_per_h: float = 150.0
    imu_accel_noise_mps2: float = 0.05
    imu_accel_bias_mps2: float = 0.05
    imu_gyro_noise_radps: float = 0.003
    imu_gyro_bias_radps: float = 0.005
    gps_h_acc_m: float = 1.8
    gps_v_acc_m: float = 3.0
    weight_bias_pct: float = 5.0


@dataclass(frozen=True)
class Scenario:
    name: str
    vehicle: str
    start_latitude_deg: float
    start_longitude_deg: float
    start_time: dt.datetime
    route: Route
    terrain: Terrain = field(default_factory=Terrain)
    tunnel: tuple[Tunnel, ...] = ()
    payload: Payload = field(default_factory=Payload)
    driver: Driver = field(default_factory=Driver)
    sensors: Sensors = field(default_factory=Sensors)
    start_heading_deg: float = 0.0
    description: str = ""
    realism: Realism = IDEAL
    """Default realism level of drives of this scenario (``[realism]`` table)."""
    base_dir: Path = Path(".")
    """Folder relative paths in the file (``route.vdri``) are resolved against."""

    @property
    def start_epoch_ns(self) -> int:
        """Wall-clock start of the drive [ns since 1970, UTC]."""
        return int(round(self.start_time.timestamp())) * 1_000_000_000


SCENARIOS = {
    "urban-delivery": "urban-delivery.toml",
    "regional-tunnel": "regional-tunnel.toml",
    "long-haul": "long-haul.toml",
}
"""Scenarios shipped with the package, by name."""

# (min, max) of sensible values; outside is most likely a wrong unit.
_RANGES = {
    "start_latitude_deg": (-59.0, 59.0),  # SRTM coverage
    "start_longitude_deg": (-180.0, 180.0),
    "start_heading_deg": (-360.0, 360.0),
    "length_m": (1.0, 1_000_000.0),
    "speed_kmh": (1.0, 130.0),
    "stop_s": (0.0, 36_000.0),
    "initial_stop_s": (0.0, 3_600.0),
    "final_stop_s": (0.0, 3_600.0),
    "base_altitude_m": (-400.0, 8_000.0),
    "hill_amplitude_m": (0.0, 500.0),
    "hill_wavelengths_m": (200.0, 200_000.0),
    "cut_fill_m": (0.0, 20.0),
    "offroad_hill_amplitude_m": (0.0, 1_000.0),
    "curviness_deg": (0.0, 180.0),
    "seed": (0, 2**31),
    "start_m": (0.0, 1_000_000.0),
    "depth_m": (0.0, 500.0),
    "initial_kg": (0.0, 100_000.0),
    "after_stop_kg": (0.0, 100_000.0),
    "max_accel_mps2": (0.05, 3.0),
    "comfort_decel_mps2": (0.1, 3.0),
    "max_decel_mps2": (0.2, 8.0),
    "speed_gain_per_s": (0.01, 10.0),
    "traffic": (0.0, 2.0),
    "downhill_overspeed_kmh": (0.0, 20.0),
    "imu_rate_hz": (10.0, 952.0),
    "gps_rate_hz": (0.1, 10.0),
    "weight_bias_pct": (0.0, 50.0),
}
_NOISE_MAX = 1_000.0


def _value(where: str, key: str, value, annotation: str):
    if annotation.startswith("tuple[float"):
        if not isinstance(value, list) or not all(is_number(v) for v in value):
            raise ScenarioFileError(f"{where}.{key}: expected a list of numbers, got {value!r}")
        return tuple(float(_value(where, key, v, "float")) for v in value)
    if annotation.startswith("str"):
        return check_text(where, key, value, ScenarioFileError)
    return check_number(where, key, value, _RANGES.get(key, (0.0, _NOISE_MAX)), ScenarioFileError,
                        whole=annotation == "int")


def _table(cls, data, where: str, skip: tuple[str, ...] = ()) -> dict:
    allowed = {f.name for f in fields(cls)} - {"base_dir"}
    return table_kwargs(cls, data, where, _value, ScenarioFileError, allowed, ignore=skip)


def _array(cls, data, where: str) -> tuple:
    if not isinstance(data, list):
        raise ScenarioFileError(f"{where}: expected an array of tables ([[...]]), got {data!r}")
    return tuple(cls(**_table(cls, item, f"{where}[{i}]")) for i, item in enumerate(data))


_TOP = {"scenario", "route", "terrain", "tunnel", "payload", "driver", "sensors", "realism"}


def _realism(data, where: str) -> Realism:
    """``[realism]``: ``level`` plus any error sizes to override (`realism.Realism`)."""
    if not isinstance(data, dict):
        raise ScenarioFileError(f"{where}: expected a table, got {data!r}")
    sizes = dict(data)
    level = sizes.pop("level", "ideal")
    try:
        return realism_level(level, **sizes)
    except UserError as exc:
        raise ScenarioFileError(f"{where}: {exc}") from None


def scenario_from_dict(data: dict, source: str = "<scenario>", base_dir: Path = Path(".")) -> Scenario:
    """Validate a parsed scenario file and build the `Scenario`."""
    for table in data:
        if table not in _TOP:
            raise ScenarioFileError(f"{source}: unknown table [{table}] (known: {', '.join(sorted(_TOP))})")
    for table in ("scenario", "route"):
        if table not in data:
            raise ScenarioFileError(f"{source}: missing table [{table}]")
    head = dict(data["scenario"]) if isinstance(data["scenario"], dict) else data["scenario"]
    start = head.pop("start_time", None) if isinstance(head, dict) else None
    kwargs = _table(Scenario, head, f"{source} [scenario]",
                    skip=("route", "terrain", "tunnel", "payload", "driver", "sensors", "start_time", "realism"))
    if start is None:
        raise ScenarioFileError(f"{source} [scenario]: missing key 'start_time' (e.g. 2025-05-14T06:30:00Z)")
    if not isinstance(start, dt.datetime) or start.tzinfo is None:
        raise ScenarioFileError(f"{source} [scenario].start_time: expected a TOML date-time with time zone "
                                f"(e.g. 2025-05-14T06:30:00Z), got {start!r}")
    if kwargs["vehicle"] not in VEHICLE_EXAMPLES and not (base_dir / kwargs["vehicle"]).is_file():
        raise ScenarioFileError(f"{source} [scenario].vehicle: '{kwargs['vehicle']}' is neither a shipped "
                                f"vehicle ({', '.join(VEHICLE_EXAMPLES)}) nor a vehicle file beside the scenario")
    route_data = data["route"]
    route = _table(Route, route_data, f"{source} [route]", skip=("section",))
    if isinstance(route_data, dict) and "section" in route_data:
        route["section"] = _array(Section, route_data["section"], f"{source} [[route.section]]")
    if bool(route.get("section")) == bool(route.get("vdri")):
        raise ScenarioFileError(f"{source} [route]: give either [[route.section]] tables or vdri = \"cycle.vdri\"")
    if route.get("vdri") and not (base_dir / route["vdri"]).is_file():
        raise ScenarioFileError(f"{source} [route].vdri: cycle file {base_dir / route['vdri']} not found")
    kwargs["route"] = Route(**route)
    kwargs["terrain"] = Terrain(**_table(Terrain, data.get("terrain", {}), f"{source} [terrain]"))
    kwargs["tunnel"] = _array(Tunnel, data.get("tunnel", []), f"{source} [[tunnel]]")
    kwargs["payload"] = Payload(**_table(Payload, data.get("payload", {}), f"{source} [payload]"))
    driver = Driver(**_table(Driver, data.get("driver", {}), f"{source} [driver]"))
    if not driver.comfort_decel_mps2 < driver.max_decel_mps2:
        raise ScenarioFileError(f"{source} [driver]: comfort_decel_mps2 must be below max_decel_mps2")
    kwargs["driver"] = driver
    kwargs["sensors"] = Sensors(**_table(Sensors, data.get("sensors", {}), f"{source} [sensors]"))
    kwargs["realism"] = _realism(data.get("realism", {}), f"{source} [realism]")
    if not kwargs["terrain"].hill_wavelengths_m:
        raise ScenarioFileError(f"{source} [terrain].hill_wavelengths_m: give at least one wavelength")
    return Scenario(start_time=start, base_dir=base_dir, **kwargs)


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a scenario file, or one of the shipped `SCENARIOS` by name."""
    name = str(name_or_path)
    if name in SCENARIOS:
        ref = resources.files("haulprofile.analysis.virtual_truck.scenarios").joinpath(SCENARIOS[name])
        text, source, base_dir = ref.read_text(), name, Path(str(ref)).parent
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise ScenarioFileError(
                f"scenario file {path} not found (give a TOML file or one of: {', '.join(SCENARIOS)})")
        text, source, base_dir = path.read_text(), str(path), path.resolve().parent
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioFileError(f"{source}: not valid TOML: {exc}") from None
    return scenario_from_dict(data, source, base_dir)
