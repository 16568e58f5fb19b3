"""The electric truck on a cycle: parameters from the vehicle file, the kernel run, the results
(energy per km at battery and wheel, SOC trace, machine operating-point residence, misses)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .. import checks, road_load
from ..runs import true_runs
from ..vehicle import Vehicle
from . import kernel as K
from .cycle import SimCycle, SimulationInputError

RPM_PER_RADPS = 60.0 / (2.0 * np.pi)


@dataclass(frozen=True)
class DriverSettings:
    """Driver and integration settings [choice, see docs/simulation.md]."""

    time_step_s: float = 0.1
    controller_time_constant_s: float = 1.0
    max_acceleration_mps2: float = 1.0
    planned_deceleration_mps2: float = 0.5
    max_deceleration_mps2: float = 5.0
    speed_tolerance_mps: float = 0.5


@dataclass
class SimulationResult:
    """One simulated cycle: the trace, its numbers, the machine's residence and the missed targets."""

    trace: pd.DataFrame
    numbers: dict
    """Energy per km [kWh/km], SOC, missed targets, distances and masses (`summarise`)."""
    residence_s: np.ndarray
    residence_speed_edges_rpm: np.ndarray
    residence_torque_edges_nm: np.ndarray
    misses: pd.DataFrame = field(default_factory=pd.DataFrame)

    def summary(self) -> dict:
        return self.numbers


def efficiency_map(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a machine efficiency map CSV (columns speed_rpm, torque_nm, efficiency on a full
    regular grid) into (speed grid [rad/s], |torque| grid [Nm], efficiency table)."""
    path = Path(path)
    if not path.is_file():
        raise SimulationInputError(f"efficiency map {path} not found (efficiency_map_csv in the vehicle file)")
    try:
        frame = pd.read_csv(path)
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise SimulationInputError(f"{path}: not a CSV table ({str(exc).splitlines()[0]})") from None
    needed = {"speed_rpm", "torque_nm", "efficiency"}
    if not needed <= set(frame.columns):
        raise SimulationInputError(f"{path}: an efficiency map needs columns speed_rpm, torque_nm, efficiency")
    for column in sorted(needed):
        values = pd.to_numeric(frame[column], errors="coerce")
        if values.isna().any() or not np.isfinite(values.to_numpy(float)).all():
            row = int(np.flatnonzero(values.isna() | ~np.isfinite(values.to_numpy(float)))[0]) + 2
            raise SimulationInputError(f"{path}: {column} must be a finite number on every row "
                                       f"(line {row} has {frame[column].iloc[row - 2]!r})")
        frame[column] = values.astype(float)
    table = frame.pivot_table(index="speed_rpm", columns="torque_nm", values="efficiency")
    if table.isna().any().any():
        raise SimulationInputError(f"{path}: the efficiency map must fill a regular speed x torque grid")
    eff = table.to_numpy(float)
    if np.any(eff <= 0) or np.any(eff > 1):
        raise SimulationInputError(f"{path}: efficiencies must lie in (0, 1]")
    return table.index.to_numpy(float) / RPM_PER_RADPS, table.columns.to_numpy(float), eff


def pack_parameters(vehicle: Vehicle, settings: DriverSettings, t_end_s: float) -> np.ndarray:
    """The kernel's parameter vector (indices `kernel.P_*`)."""
    ep = vehicle.electric_powertrain
    if ep is None:
        raise SimulationInputError(f"vehicle '{vehicle.name}' has no [electric_powertrain] table to simulate")
    p = np.zeros(K.N_PARAMETERS)
    p[K.P_DT] = settings.time_step_s
    p[K.P_AERO] = float(road_load.aero_force_n(1.0, vehicle.drag_coefficient, vehicle.frontal_area_m2))
    p[K.P_ROT_MASS] = ep.rotating_mass_kg
    p[K.P_WHEEL_RADIUS] = vehicle.wheel_radius_m
    p[K.P_GEAR_EFF] = vehicle.driveline_efficiency
    p[K.P_MAX_TORQUE] = ep.machine_max_torque_nm
    p[K.P_MAX_POWER] = ep.machine_max_power_w
    p[K.P_MAX_SPEED] = ep.machine_max_speed_rpm / RPM_PER_RADPS
    p[K.P_MAX_RECUP] = ep.max_recuperation_power_w if ep.max_recuperation_power_w is not None else ep.machine_max_power_w
    p[K.P_INV_EFF] = ep.inverter_efficiency
    p[K.P_MACHINE_EFF] = ep.machine_efficiency
    p[K.P_OCV] = ep.battery_voltage_v
    p[K.P_RESISTANCE] = ep.battery_internal_resistance_ohm
    p[K.P_CHARGE_C] = ep.battery_capacity_kwh * 3.6e6 / ep.battery_voltage_v
    p[K.P_SOC0] = ep.initial_soc
    p[K.P_CTRL_TAU] = settings.controller_time_constant_s
    p[K.P_ACC_MAX] = settings.max_acceleration_mps2
    p[K.P_DEC_BRAKE] = settings.planned_deceleration_mps2
    p[K.P_BRAKE_MAX] = settings.max_deceleration_mps2
    p[K.P_T_END] = t_end_s
    p[K.P_MIN_SOC] = ep.min_soc
    return p


def _power_series(value, name: str) -> tuple[np.ndarray, np.ndarray]:
    """A constant [W] or a (time_s, power_w) pair / DataFrame as (time grid, power)."""
    if isinstance(value, pd.DataFrame):
        if not {"time_s", "power_w"} <= set(value.columns):
            raise SimulationInputError(f"{name}: a power time series needs columns time_s and power_w")
        value = (value["time_s"].to_numpy(float), value["power_w"].to_numpy(float))
    if isinstance(value, tuple):
        time, power = (np.asarray(v, float) for v in value)
        if time.shape != power.shape or len(time) == 0 or np.any(np.diff(time) <= 0):
            raise SimulationInputError(f"{name}: time_s must rise strictly and match power_w")
        return time, power
    return np.zeros(1), np.full(1, float(value))


def _loads_on_one_grid(aux, epto, obc):
    series = [_power_series(aux, "auxiliary power"), _power_series(epto, "ePTO power"),
              _power_series(obc, "OBC power")]
    grid = np.unique(np.concatenate([t for t, _ in series]))
    return grid, [np.interp(grid, t, w) for t, w in series]


def kernel_arguments(cycle: SimCycle, vehicle: Vehicle, *, aux_power_w=None, epto_power_w=0.0, obc_power_w=0.0,
                     settings: DriverSettings = DriverSettings()) -> tuple:
    """The arguments of `kernel.run_kernel` for one run, ``out`` included."""
    p = pack_parameters(vehicle, settings, t_end_s=_time_budget_s(cycle))
    ep = vehicle.electric_powertrain
    ratios = np.asarray(ep.gear_ratios, float) * (ep.axle_ratio or vehicle.axle_ratio or 1.0)
    if ep.efficiency_map_csv:
        map_speed, map_torque, map_eff = efficiency_map(ep.efficiency_map_csv)
    else:
        map_speed, map_torque, map_eff = np.empty(0), np.empty(0), np.empty((0, 0))
    load_time, (aux, epto, obc) = _loads_on_one_grid(
        ep.auxiliary_power_w if aux_power_w is None else aux_power_w, epto_power_w, obc_power_w)
    f_roll, f_climb = cycle.road_forces_n(vehicle)
    steps = _expected_steps(cycle, settings.time_step_s)
    checks.rows(steps, f"simulating {cycle.name} at {settings.time_step_s:g} s steps",
                "is the cycle's time or distance in the right unit?")
    out = np.empty((K.N_COLUMNS, steps))
    arrays = (cycle.position, cycle.target_speed_mps, cycle.gradient_pct, f_roll, f_climb, cycle.mass_kg,
              cycle.stop_distance_m, cycle.stop_time_s, load_time, aux, epto, obc, p, ratios, map_speed, map_torque,
              map_eff)
    # writable: numba compiles a kernel once per read-only flag of its arrays (a column of a frame
    # read from Parquet is read-only), and run_kernel takes 6 s to compile
    return (cycle.time_based, *(np.require(a, requirements=["C", "W"]) for a in arrays), out)


def simulate_cycle(cycle: SimCycle, vehicle: Vehicle, *, aux_power_w=None, epto_power_w=0.0, obc_power_w=0.0,
             settings: DriverSettings = DriverSettings()) -> SimulationResult:
    """Drive ``vehicle``'s electric powertrain over ``cycle``. Powers [W] are constants or
    (time_s, power_w) series; auxiliary power defaults to the vehicle file's.

    Parameters
    ----------
    cycle : SimCycle
        Distance-based (`distance_cycle`, `read_cycle` of a ``.vdri``) or time-based (`time_cycle`).
    vehicle : Vehicle
        With an ``[electric_powertrain]`` table.
    aux_power_w, epto_power_w, obc_power_w : float or (time_s, power_w), optional
        Auxiliary, ePTO and on-board charger power [W]; the charger feeds the DC bus.
    settings : DriverSettings
        Integration step [s] and the driver model.

    Returns
    -------
    SimulationResult
        ``trace`` (per step: speed [m/s], wheel and machine torque [Nm], battery power [W], SOC),
        ``numbers`` (energy per km [kWh/km], SOC, missed targets), machine residence [s], ``misses``.

    References
    ----------
    physics.md, simulation section: road forces from paper equations (2)-(3), acceleration (4).
    """
    args = kernel_arguments(cycle, vehicle, aux_power_w=aux_power_w, epto_power_w=epto_power_w,
                            obc_power_w=obc_power_w, settings=settings)
    n = K.run_kernel(*args)
    while n == -1:
        args = args[:-1] + (np.empty((K.N_COLUMNS, 2 * args[-1].shape[1])),)
        n = K.run_kernel(*args)
    if n < 0:
        raise SimulationInputError(f"{cycle.name}: the truck did not finish the cycle within "
                                   f"{args[13][K.P_T_END]:.0f} s (stalled on a gradient it cannot climb?)")
    return summarise(trace_frame(args[-1][:, :n]), cycle, vehicle, settings)


def _expected_steps(cycle: SimCycle, dt: float) -> int:
    """Rows to allocate: the cycle's duration at 80 % of its mean target speed, plus stops."""
    if cycle.time_based:
        return int((cycle.position[-1] - cycle.position[0]) / dt) + 16
    distance = float(cycle.position[-1] - cycle.position[0])
    moving = cycle.target_speed_mps[cycle.target_speed_mps > 0]
    mean_speed = float(moving.mean()) if len(moving) else 1.0
    return int((distance / (0.8 * mean_speed) + cycle.stop_time_s.sum() + 60.0) / dt) + 16


def _time_budget_s(cycle: SimCycle) -> float:
    if cycle.time_based:
        return float(cycle.position[-1] - cycle.position[0]) + 1.0
    distance = float(cycle.position[-1] - cycle.position[0])
    return distance / 1.0 + float(cycle.stop_time_s.sum()) + 600.0


COLUMNS = {
    "time_s": K.C_TIME, "distance_m": K.C_DIST, "speed_mps": K.C_SPEED, "target_speed_mps": K.C_TARGET,
    "accel_mps2": K.C_ACCEL, "driver_state": K.C_STATE, "gear": K.C_GEAR, "gradient_pct": K.C_GRADIENT,
    "traction_force_n": K.C_F_TRAC, "friction_brake_force_n": K.C_F_FRIC, "rolling_force_n": K.C_F_ROLL,
    "climbing_force_n": K.C_F_CLIMB, "aero_force_n": K.C_F_AERO, "machine_speed_radps": K.C_M_SPEED,
    "machine_torque_nm": K.C_M_TORQUE, "traction_limited": K.C_LIMITED, "soc": K.C_SOC,
    "battery_current_a": K.C_CURRENT, "battery_terminal_power_w": K.C_P_BATT, "step_distance_m": K.C_DS,
    "wheel_traction_energy_j": K.C_E_TRAC, "friction_brake_energy_j": K.C_E_FRIC,
    "gear_loss_j": K.C_E_GEAR_LOSS, "machine_loss_j": K.C_E_MACHINE_LOSS, "inverter_loss_j": K.C_E_INV_LOSS,
    "battery_loss_j": K.C_E_BATT_LOSS, "battery_energy_j": K.C_E_BATT, "auxiliary_energy_j": K.C_E_AUX,
    "epto_energy_j": K.C_E_EPTO, "obc_energy_j": K.C_E_OBC,
}
STATE_NAMES = {K.STANDSTILL: "standstill", K.DRIVE: "drive", K.COAST: "coast", K.BRAKE: "brake"}


def trace_frame(out: np.ndarray) -> pd.DataFrame:
    """The kernel's output (a row per quantity, a column per step) as a named DataFrame (one row
    per step); the columns are views of ``out``, not copies."""
    frame = pd.DataFrame({name: out[column] for name, column in COLUMNS.items()}, copy=False)
    for column in ("driver_state", "gear", "traction_limited"):
        frame[column] = frame[column].astype(np.int8)
    frame["machine_speed_rpm"] = frame["machine_speed_radps"] * RPM_PER_RADPS
    return frame


LONG_MISS_S = 2.0
"""A miss at least this long [s] is one a driver notices (a gear change or a gust below it is not):
the report and the command's line count these."""


def find_misses(trace: pd.DataFrame, tolerance_mps: float) -> pd.DataFrame:
    """Intervals where the powertrain (or an empty battery) kept the truck more than
    ``tolerance_mps`` below its target speed: where, how long and by how much."""
    deficit = (trace["target_speed_mps"] - trace["speed_mps"]).to_numpy()
    missed = (trace["traction_limited"].to_numpy() > 0) & (deficit > tolerance_mps)
    columns = ["start_time_s", "end_time_s", "start_distance_m", "end_distance_m", "duration_s",
               "max_speed_deficit_mps", "mean_speed_deficit_mps"]
    if not missed.any():
        return pd.DataFrame(columns=columns)
    time, dist = trace["time_s"].to_numpy(), trace["distance_m"].to_numpy()
    dt = time[1] - time[0] if len(time) > 1 else 0.0
    rows = [(time[a], time[b - 1] + dt, dist[a], dist[b - 1], time[b - 1] + dt - time[a],
             deficit[a:b].max(), deficit[a:b].mean()) for a, b in true_runs(missed)]
    return pd.DataFrame(rows, columns=columns)


def summarise(trace: pd.DataFrame, cycle: SimCycle, vehicle: Vehicle, settings: DriverSettings) -> SimulationResult:
    """Energies [kWh], energy per km, SOC, residence matrix and misses of one run."""
    ep = vehicle.electric_powertrain
    dt = settings.time_step_s
    distance_km = float(trace["step_distance_m"].sum()) / 1000.0
    kwh = 1.0 / 3.6e6
    e_trac = trace["wheel_traction_energy_j"].to_numpy()
    wheel_total = e_trac - trace["friction_brake_energy_j"].to_numpy()
    battery_terminal = float(trace["battery_terminal_power_w"].sum() * dt)
    per_km = (lambda e: e / distance_km) if distance_km > 0 else (lambda e: float("nan"))
    speed_edges = np.linspace(0.0, ep.machine_max_speed_rpm, 21)
    torque_edges = np.linspace(-ep.machine_max_torque_nm, ep.machine_max_torque_nm, 21)
    moving = trace["driver_state"].to_numpy() != K.STANDSTILL
    residence, _, _ = np.histogram2d(trace["machine_speed_rpm"].to_numpy()[moving],
                                     np.clip(trace["machine_torque_nm"].to_numpy()[moving],
                                             torque_edges[0], torque_edges[-1]),
                                     bins=[speed_edges, torque_edges], weights=np.full(moving.sum(), dt))
    misses = find_misses(trace, settings.speed_tolerance_mps)
    soc = trace["soc"].to_numpy()
    final_soc = soc[-1] - trace["battery_current_a"].iloc[-1] * dt / (
        ep.battery_capacity_kwh * 3.6e6 / ep.battery_voltage_v)
    summary = {
        "cycle": cycle.name,
        "time_based": cycle.time_based,
        "time_step_s": dt,
        "duration_s": float(len(trace) * dt),
        "distance_km": distance_km,
        "mean_mass_kg": float(np.mean(cycle.mass_kg)),
        "battery_terminal_energy_kwh": battery_terminal * kwh,
        "battery_internal_energy_kwh": float(trace["battery_energy_j"].sum()) * kwh,
        "battery_kwh_per_km": per_km(battery_terminal * kwh),
        "wheel_positive_energy_kwh": float(np.clip(wheel_total, 0, None).sum()) * kwh,
        "wheel_positive_kwh_per_km": per_km(float(np.clip(wheel_total, 0, None).sum()) * kwh),
        "wheel_net_traction_kwh_per_km": per_km(float(e_trac.sum()) * kwh),
        "recuperated_at_wheel_kwh": float(-np.clip(e_trac, None, 0).sum()) * kwh,
        "friction_brake_energy_kwh": float(trace["friction_brake_energy_j"].sum()) * kwh,
        "auxiliary_energy_kwh": float(trace["auxiliary_energy_j"].sum()) * kwh,
        "initial_soc": float(soc[0]),
        "final_soc": float(final_soc),
        "soc_below_minimum": bool(final_soc < ep.min_soc or np.any(soc < ep.min_soc)),
        "max_overspeed_mps": float(np.max(trace["speed_mps"] - trace["target_speed_mps"])),
        "standstill_s": float(np.sum(~moving) * dt),
        "missed_target_intervals": int(len(misses)),
        "missed_target_long_intervals": int((misses["duration_s"] >= LONG_MISS_S).sum()) if len(misses) else 0,
        "missed_target_long_min_s": LONG_MISS_S,
        "missed_target_s": float(misses["duration_s"].sum()) if len(misses) else 0.0,
        "max_speed_deficit_mps": float(misses["max_speed_deficit_mps"].max()) if len(misses) else 0.0,
    }
    return SimulationResult(trace, summary, residence, speed_edges, torque_edges, misses)
