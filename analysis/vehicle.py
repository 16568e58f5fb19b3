"""The vehicle file (TOML): Table 1 of the paper, driveline, engine and a target e-powertrain.

See ``docs/vehicle-file.md``. Loading validates every key: an unknown key, a missing key, a value
of the wrong type or an impossible value (mm given where m is asked) is a `VehicleFileError` that
names the file, table and key.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, fields, replace
from importlib import resources
from pathlib import Path

from .errors import UserError
from haulprofile.contract.toml_tables import check_number, check_text, is_number, table_kwargs


class VehicleFileError(UserError):
    pass


@dataclass(frozen=True)
class Engine:
    """Combustion engine and gearbox of the reference truck (what its CAN bus reports)."""

    idle_speed_rpm: float = 600.0
    max_speed_rpm: float = 2100.0
    max_power_w: float = 330_000.0
    shift_up_speed_rpm: float = 1500.0
    shift_down_speed_rpm: float = 900.0
    shift_time_s: float = 1.0


@dataclass(frozen=True)
class ElectricPowertrain:
    """Target battery-electric powertrain for the longitudinal simulation."""

    machine_max_torque_nm: float
    machine_max_power_w: float
    machine_max_speed_rpm: float
    battery_capacity_kwh: float
    battery_voltage_v: float
    machine_efficiency: float = 0.93
    efficiency_map_csv: str | None = None
    gear_ratios: tuple[float, ...] = (1.0,)
    axle_ratio: float | None = None
    inverter_efficiency: float = 0.97
    battery_internal_resistance_ohm: float = 0.05
    initial_soc: float = 0.9
    min_soc: float = 0.1
    max_recuperation_power_w: float | None = None
    auxiliary_power_w: float = 3_000.0
    rotating_mass_kg: float = 0.0


@dataclass(frozen=True)
class Vehicle:
    """Longitudinal parameters of one truck (paper Table 1 plus driveline)."""

    name: str
    curb_mass_kg: float
    drag_coefficient: float
    frontal_area_m2: float
    rolling_resistance_coefficient: float
    wheel_radius_m: float
    driveline_efficiency: float
    gear_ratios: tuple[float, ...] | None = None
    axle_ratio: float | None = None
    engine_reference_torque_nm: float | None = None
    engine: Engine | None = None
    electric_powertrain: ElectricPowertrain | None = None
    max_payload_kg: float | None = None

    @property
    def total_ratios(self) -> tuple[float, ...] | None:
        """Overall ratio engine → wheel per gear (gear ratio × axle ratio)."""
        if self.gear_ratios is None or self.axle_ratio is None:
            return None
        return tuple(g * self.axle_ratio for g in self.gear_ratios)


# (min, max) of physically possible values; a value outside is most likely a wrong unit.
_RANGES = {
    "curb_mass_kg": (500.0, 60_000.0),
    "drag_coefficient": (0.1, 2.0),
    "frontal_area_m2": (1.0, 20.0),
    "rolling_resistance_coefficient": (0.0005, 0.05),
    "wheel_radius_m": (0.15, 1.5),
    "driveline_efficiency": (0.3, 1.0),
    "axle_ratio": (1.0, 15.0),
    "engine_reference_torque_nm": (50.0, 6_000.0),
    "max_payload_kg": (0.0, 100_000.0),
    "idle_speed_rpm": (200.0, 1_500.0),
    "max_speed_rpm": (1_000.0, 8_000.0),
    "max_power_w": (10_000.0, 1_000_000.0),
    "shift_up_speed_rpm": (500.0, 8_000.0),
    "shift_down_speed_rpm": (300.0, 5_000.0),
    "shift_time_s": (0.0, 5.0),
    "machine_max_torque_nm": (10.0, 50_000.0),
    "machine_max_power_w": (10_000.0, 2_000_000.0),
    "machine_max_speed_rpm": (500.0, 30_000.0),
    "battery_capacity_kwh": (1.0, 2_000.0),
    "battery_voltage_v": (12.0, 1_500.0),
    "machine_efficiency": (0.3, 1.0),
    "inverter_efficiency": (0.3, 1.0),
    "battery_internal_resistance_ohm": (0.0, 5.0),
    "initial_soc": (0.0, 1.0),
    "min_soc": (0.0, 1.0),
    "max_recuperation_power_w": (0.0, 2_000_000.0),
    "auxiliary_power_w": (0.0, 200_000.0),
    "rotating_mass_kg": (0.0, 10_000.0),
}

_VEHICLE_TABLE_KEYS = {f.name for f in fields(Vehicle)} - {"engine", "electric_powertrain", "max_payload_kg"}
_TOP_TABLES = {"vehicle", "engine", "electric_powertrain", "load"}


def _check_value(where: str, key: str, value, annotation: str):
    if "tuple" in annotation:
        if not isinstance(value, list) or not value or not all(is_number(v) for v in value):
            raise VehicleFileError(f"{where}.{key}: expected a non-empty list of numbers, got {value!r}")
        if any(v <= 0 for v in value):
            raise VehicleFileError(f"{where}.{key}: every ratio must be positive, got {value!r}")
        return tuple(float(v) for v in value)
    if annotation.startswith("str"):
        return check_text(where, key, value, VehicleFileError)
    return check_number(where, key, value, _RANGES.get(key, (float("-inf"), float("inf"))), VehicleFileError)


def _build(cls, table: dict, where: str, allowed: set[str] | None = None):
    return table_kwargs(cls, table, where, _check_value, VehicleFileError, allowed)


def _deliverable(ep: "ElectricPowertrain", where: str) -> "ElectricPowertrain":
    """The battery must be able to deliver the machine's peak power at all: at most U²/(4R) [W]
    flows out of a source of open-circuit voltage U and internal resistance R (half of it lost in
    R). A 12 V / 5 Ω battery (7.2 W) for a 300 kW machine once "delivered" 45 kWh while charging."""
    if ep.battery_internal_resistance_ohm > 0:
        peak_w = ep.battery_voltage_v ** 2 / (4 * ep.battery_internal_resistance_ohm)
        if peak_w < ep.machine_max_power_w:
            raise VehicleFileError(
                f"{where}: a {ep.battery_voltage_v:g} V battery of {ep.battery_internal_resistance_ohm:g} Ω delivers at "
                f"most {peak_w / 1000:.3g} kW (U²/4R), below machine_max_power_w {ep.machine_max_power_w / 1000:.3g} kW; "
                "check battery_voltage_v and battery_internal_resistance_ohm")
    return ep


def vehicle_from_dict(data: dict, source: str = "<vehicle>") -> Vehicle:
    """Validate a parsed vehicle file and build the `Vehicle`."""
    for table in data:
        if table not in _TOP_TABLES:
            raise VehicleFileError(f"{source}: unknown table [{table}] (known: {', '.join(sorted(_TOP_TABLES))})")
    if "vehicle" not in data:
        raise VehicleFileError(f"{source}: missing table [vehicle]")
    kwargs = _build(Vehicle, data["vehicle"], f"{source} [vehicle]", _VEHICLE_TABLE_KEYS)
    if "load" in data:
        kwargs.update(_build(Vehicle, data["load"], f"{source} [load]", {"max_payload_kg"}))
    if "engine" in data:
        kwargs["engine"] = Engine(**_build(Engine, data["engine"], f"{source} [engine]"))
    if "electric_powertrain" in data:
        ep = _build(ElectricPowertrain, data["electric_powertrain"], f"{source} [electric_powertrain]")
        if ep.get("min_soc", 0.1) >= ep.get("initial_soc", 0.9):
            raise VehicleFileError(f"{source} [electric_powertrain]: min_soc must be below initial_soc")
        kwargs["electric_powertrain"] = _deliverable(ElectricPowertrain(**ep), f"{source} [electric_powertrain]")
    if (kwargs.get("gear_ratios") is None) != (kwargs.get("axle_ratio") is None):
        raise VehicleFileError(f"{source} [vehicle]: gear_ratios and axle_ratio go together; give both or neither")
    engine = kwargs.get("engine")
    if engine and engine.shift_down_speed_rpm >= engine.shift_up_speed_rpm:
        raise VehicleFileError(f"{source} [engine]: shift_down_speed_rpm must be below shift_up_speed_rpm")
    return Vehicle(**kwargs)


EXAMPLES = {"rigid-18t": "rigid-18t.toml", "tractor-40t": "tractor-40t.toml"}
"""Example vehicles shipped with the package, by name."""


def load_vehicle(path_or_name: str | Path) -> Vehicle:
    """Load a vehicle file, or one of the shipped `EXAMPLES` by name.

    Parameters
    ----------
    path_or_name : str or Path
        A TOML vehicle file (docs/vehicle-file.md), ``"rigid-18t"`` / ``"tractor-40t"``, or a VECTO
        job (``.vecto``) or vehicle (``.vveh``) file (`analysis.vecto_vehicle`).

    Returns
    -------
    Vehicle
        Masses [kg], wheel radius [m], driving resistances, drivetrain ratios and the optional
        electric powertrain; every value checked against its physically possible range.

    References
    ----------
    The parameters of paper equations (1)-(4).
    """
    name = str(path_or_name)
    if Path(name).suffix.lower() in (".vecto", ".vveh"):  # a VECTO job or vehicle file, converted
        from .vecto_vehicle import vehicle_tables

        return vehicle_from_dict(vehicle_tables(name)[0], name)
    if name in EXAMPLES:
        text = resources.files("haulprofile.analysis.data.vehicles").joinpath(EXAMPLES[name]).read_text()
        source = name
    else:
        path = Path(path_or_name)
        if not path.is_file():
            raise VehicleFileError(
                f"vehicle file {path} not found (give a TOML file or one of: {', '.join(EXAMPLES)})")
        try:
            text, source = path.read_text(encoding="utf-8"), str(path)
        except UnicodeDecodeError as exc:
            raise VehicleFileError(f"{path}: not UTF-8 text (invalid byte at offset {exc.start}); a vehicle file "
                                   f"is TOML, saved as UTF-8") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise VehicleFileError(f"{source}: not valid TOML: {exc}") from None
    vehicle = vehicle_from_dict(data, source)
    ep = vehicle.electric_powertrain
    if name not in EXAMPLES and ep is not None and ep.efficiency_map_csv and not Path(ep.efficiency_map_csv).is_absolute():
        # efficiency_map_csv is relative to the vehicle file (docs/vehicle-file.md)
        ep = replace(ep, efficiency_map_csv=str(Path(path_or_name).parent / ep.efficiency_map_csv))
        vehicle = replace(vehicle, electric_powertrain=ep)
    return vehicle
