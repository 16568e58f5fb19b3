"""Candidates to simulations to objectives and constraints, in batches.

A candidate becomes a vehicle (the user's vehicle with the concept's driveline efficiency and
``[electric_powertrain]``), packed by the simulate stage's own `pack_parameters`, and all of a
batch run through `kernel.simulate_batch`. Constraints are g <= 0 (required / available - 1)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .. import road_load
from ..simulate import kernel as SK
from ..simulate.cycle import SimCycle
from ..simulate.model import DriverSettings, kernel_arguments, pack_parameters, simulate_cycle
from ..vehicle import ElectricPowertrain, Vehicle
from . import components as C
from . import kernel as DK
from .options import DesignOptions

N_VARIABLES = 9
CONSTRAINTS = ("gradeability", "startability", "top speed", "range with reserve", "battery power",
               "follows the cycle")
"""Names of the constraints before the thermal windows (one each, ``thermal <w> s``), static first:
the first one every candidate broke is named as binding."""
NO_REFERENCE_POWERTRAIN_KG = 3_000.0
"""Without a vehicle-file ``[electric_powertrain]``, the curb mass is taken to hold this much
powertrain (a heavy truck's diesel engine, gearbox, tank and aftertreatment) [kg, choice]."""
MAX_TIME_LOSS = 0.02
"""A candidate follows a cycle when it loses at most this share of the trip time against the same
driver without powertrain limits (distance-based: its duration; time-based: the distance it falls
short, as time) [choice: about a minute an hour; the driver model's 1 m/s^2 wish is not a target]."""
UNLIMITED = ElectricPowertrain(machine_max_torque_nm=50_000.0, machine_max_power_w=2_000_000.0,
                               machine_max_speed_rpm=30_000.0, battery_capacity_kwh=2_000.0, battery_voltage_v=800.0,
                               gear_ratios=(1.0,), axle_ratio=15.0, battery_internal_resistance_ohm=0.0,
                               max_recuperation_power_w=2_000_000.0)
"""A powertrain that never limits: the cycle as the driver model drives it."""
PEAK_TOLERANCE = 1.03
"""Where the thermal model admits the peak rating, the window may reach it by this factor: the
simulator limits torque at the step's start speed and counts power at its mean speed, so at peak
power a window's mean exceeds the peak by up to a dt / v (2.5 % at 1 m/s^2, 0.5 s, 20 m/s)."""
TOP_SPEED_MARGIN = 1.02
"""Machine speed margin over the legal top speed [-]."""


def cycle_distance_m(cycle: SimCycle) -> float:
    """Length of a cycle [m]: its distance span, or its speed trace integrated over time."""
    if cycle.time_based:
        return float(np.sum(np.diff(cycle.position) * cycle.target_speed_mps[1:]))
    return float(cycle.position[-1] - cycle.position[0])


def constraint_names(options: DesignOptions) -> list[str]:
    return list(CONSTRAINTS) + [f"thermal {w:g} s" for w in options.thermal_windows_s]


@dataclass(frozen=True)
class CycleBatch:
    """The cycle set packed for `kernel.simulate_batch`, and the static targets [N]."""

    args: tuple
    """`kernel.simulate_batch`'s cycle arguments; the road forces and mass are per candidate (`road_rows`)."""
    names: list[str]
    gradient_pct: np.ndarray
    mass_kg: np.ndarray

    def road_rows(self, vehicle: Vehicle, mass_delta_kg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F_roll (2), F_climb (3), mass) per candidate and row, each candidate's mass raised by its delta [kg]."""
        mass = self.mass_kg[None, :] + np.asarray(mass_delta_kg, float)[:, None]
        return (np.asarray(road_load.rolling_force_n(mass, self.gradient_pct[None, :],
                                                     vehicle.rolling_resistance_coefficient), float),
                np.asarray(road_load.climbing_force_n(mass, self.gradient_pct[None, :]), float), mass)


def pack_cycles(cycles: list[SimCycle], vehicle: Vehicle, aux_power_w: float, dt: float) -> CycleBatch:
    """Flat row arrays with offsets (road forces (2)-(3) from the one vehicle model, per cycle)."""
    probe = _with_powertrain(vehicle, ElectricPowertrain(1000.0, 500_000.0, 4000.0, 500.0, 750.0), 0.9)
    parts = [kernel_arguments(c, probe, aux_power_w=aux_power_w, settings=DriverSettings(time_step_s=dt)) for c in cycles]
    rows = [np.concatenate([a[k] for a in parts]) for k in range(1, 4)]
    stops = [np.concatenate([a[k] for a in parts]) for k in (7, 8)]
    starts = np.cumsum([0] + [len(a[1]) for a in parts]).astype(np.int64)
    stop_starts = np.cumsum([0] + [len(a[7]) for a in parts]).astype(np.int64)
    load = parts[0][9:13]
    args = (np.array([int(a[0]) for a in parts], np.int64), starts,
            np.array([a[-1].shape[0] for a in parts], np.int64), np.array([a[13][SK.P_T_END] for a in parts]),
            *rows, stop_starts, *stops, *load)
    return CycleBatch(args, [c.name for c in cycles], np.concatenate([a[3] for a in parts]),
                      np.concatenate([a[6] for a in parts]))


def reference_powertrain_mass_kg(vehicle: Vehicle) -> float:
    """Mass [kg] of the vehicle file's e-powertrain by the same figures (a central machine with
    its gears), or `NO_REFERENCE_POWERTRAIN_KG`."""
    ep = vehicle.electric_powertrain
    if ep is None:
        return NO_REFERENCE_POWERTRAIN_KG
    kw = ep.machine_max_power_w / 1000.0
    base, per_gear = C.KG_GEARBOX["central"]
    return (C.KG_PER_MACHINE + C.KG_PER_KW_MACHINE * kw + C.KG_PER_KVA_INVERTER * kw / C.POWER_FACTOR + base
            + per_gear * len(ep.gear_ratios) + C.KG_PER_KWH_BATTERY * ep.battery_capacity_kwh)


def _with_powertrain(vehicle: Vehicle, ep: ElectricPowertrain, efficiency: float) -> Vehicle:
    return replace(vehicle, driveline_efficiency=float(efficiency), electric_powertrain=ep)


def decode(x: np.ndarray, options: DesignOptions, voltage_v: float, wheel_radius_m: float) -> C.Candidates:
    """Unit-cube decision variables (rows) to candidates: topology, machines, gears, machine power,
    maximum speed, lowest and top ratio, inverter current (per unit of the machine's need), battery energy."""
    x = np.clip(np.atleast_2d(x), 0.0, 1.0 - 1e-12)
    allowed = [C.TOPOLOGIES.index(t) for t in options.topologies]
    topology = np.array(allowed)[(x[:, 0] * len(allowed)).astype(int)]
    machines = 1 + (x[:, 1] * options.max_machines).astype(int)
    lo = np.array([C.SPEEDS[C.TOPOLOGIES[t]][0] for t in topology])
    hi = np.array([C.SPEEDS[C.TOPOLOGIES[t]][1] for t in topology])
    speeds = lo + (x[:, 2] * (hi - lo + 1)).astype(int)
    p_lo, p_hi = options.machine_power_range_w
    power = p_lo * (p_hi / p_lo) ** x[:, 3]
    s_lo = np.array([C.SPEED_RANGE_RPM[C.TOPOLOGIES[t]][0] for t in topology])
    s_hi = np.array([C.SPEED_RANGE_RPM[C.TOPOLOGIES[t]][1] for t in topology])
    n_max = s_lo + x[:, 4] * (s_hi - s_lo)
    # top ratio: machine at its maximum speed reaches 1.0-1.6 x the legal top speed on its tyres
    wheel_radps = options.legal_top_speed_mps / wheel_radius_m
    omega_max = 2.0 * np.pi * n_max / 60.0
    top = omega_max / (wheel_radps * (TOP_SPEED_MARGIN + 0.6 * x[:, 5]))
    spread = np.where(speeds > 1, 1.0 + 4.0 * x[:, 6], 1.0)
    low = top * spread
    need_a = power / (np.sqrt(3.0) * voltage_v / np.sqrt(2.0) * C.POWER_FACTOR)
    current = need_a * (0.7 + 0.5 * x[:, 7])
    e_lo, e_hi = options.battery_energy_range_j
    energy = e_lo * (e_hi / e_lo) ** x[:, 8]
    return C.Candidates(topology, machines, speeds, power, n_max, low, top, current, energy)


@dataclass
class Evaluation:
    candidates: C.Candidates
    sizing: C.Sizing
    objectives: np.ndarray
    """(n, 2): battery kWh/km over the cycle set (not its sizing-only cycles), component cost [EUR]."""
    constraints: np.ndarray
    """(n, len(constraint_names)), feasible where every entry <= 0."""
    metrics: np.ndarray
    """(n, cycles, kernel metrics)."""


class Evaluator:
    """Everything fixed over one search: vehicle, options, packed cycles, targets."""

    def __init__(self, vehicle: Vehicle, cycles: list[SimCycle], options: DesignOptions, targets: dict,
                 daily_distance_m: float, energy_margin: float = 1.0, sizing_only: frozenset[str] = frozenset()):
        """``sizing_only``: names of cycles that judge the constraints (speed held, thermal windows,
        peaks) but not the energy per km: a stretch chosen for being the hardest would overstate it."""
        self.vehicle, self.options, self.targets = vehicle, options, targets
        ep = vehicle.electric_powertrain
        self.voltage_v = ep.battery_voltage_v if ep else 750.0
        self.resistance = (ep.battery_internal_resistance_ohm * ep.battery_capacity_kwh if ep
                           else C.RESISTANCE_ENERGY_OHM_KWH)
        self.aux_w = (options.auxiliary_power_w if options.auxiliary_power_w is not None
                      else (ep.auxiliary_power_w if ep else 4_000.0))
        self.rotating_mass_kg = ep.rotating_mass_kg if ep else 0.0
        self.reference_mass_kg = reference_powertrain_mass_kg(vehicle)
        self.batch = pack_cycles(cycles, vehicle, self.aux_w, options.time_step_s)
        self.daily_distance_m, self.energy_margin = daily_distance_m, energy_margin
        self.window_steps = np.array([max(1, round(w / options.time_step_s)) for w in options.thermal_windows_s],
                                     np.int64)
        self.w_pu, self.t_pu, self.map_eff = C.reference_map()
        self.settings = DriverSettings(time_step_s=options.time_step_s)
        free = [simulate_cycle(c, replace(vehicle, electric_powertrain=UNLIMITED), settings=self.settings).numbers
                for c in cycles]
        self.free_duration_s = np.array([f["duration_s"] for f in free])
        self.free_distance_m = np.array([f["distance_km"] * 1000.0 for f in free])
        self.time_based = np.array([c.time_based for c in cycles])
        self.in_consumption = np.array([c.name not in sizing_only for c in cycles])
        self.evaluated = 0

    def decode(self, x) -> C.Candidates:
        return decode(x, self.options, self.voltage_v, self.vehicle.wheel_radius_m)

    def powertrain(self, c: C.Candidates, s: C.Sizing, i: int, map_csv: str | None = None) -> Vehicle:
        """Candidate ``i`` as the vehicle `analyze simulate` drives (its ``[electric_powertrain]``)."""
        ratios = s.ratios[i][np.isfinite(s.ratios[i])]
        central = int(c.topology[i]) == 0
        axle = (self.vehicle.axle_ratio or 1.0) if central else 1.0
        soc_mid, half = 0.5, 0.5 * self.options.usable_soc_window
        ep = ElectricPowertrain(
            machine_max_torque_nm=float(s.peak_torque_nm[i]), machine_max_power_w=float(s.peak_power_w[i]),
            machine_max_speed_rpm=float(c.machine_max_speed_rpm[i]),
            battery_capacity_kwh=float(c.battery_energy_j[i] / 3.6e6), battery_voltage_v=self.voltage_v,
            efficiency_map_csv=map_csv, gear_ratios=tuple(float(r / axle) for r in ratios), axle_ratio=float(axle),
            inverter_efficiency=0.975, battery_internal_resistance_ohm=float(s.battery_resistance_ohm[i]),
            initial_soc=round(soc_mid + half, 9), min_soc=round(soc_mid - half, 9), max_recuperation_power_w=float(s.peak_power_w[i]),
            auxiliary_power_w=float(self.aux_w), rotating_mass_kg=self.rotating_mass_kg)
        concept = _with_powertrain(self.vehicle, ep, s.driveline_efficiency[i])
        return replace(concept, curb_mass_kg=float(self.vehicle.curb_mass_kg + self.mass_delta_kg(s)[i]))

    def mass_delta_kg(self, s: C.Sizing) -> np.ndarray:
        """The concept's powertrain mass over the one the vehicle's curb mass holds [kg]."""
        return s.mass_kg - self.reference_mass_kg

    def machine_map(self, s: C.Sizing, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Candidate ``i``'s scaled map: speed [rad/s], |torque| [Nm] grids and efficiency."""
        return self.w_pu * s.base_speed_radps[i], self.t_pu * s.peak_torque_nm[i], self.map_eff

    def simulate(self, c: C.Candidates, s: C.Sizing) -> np.ndarray:
        n = len(c)
        params = np.empty((n, SK.N_PARAMETERS))
        ratios = np.zeros((n, 4))
        n_ratios = np.zeros(n, np.int64)
        speed_axes = np.empty((n, len(self.w_pu)))
        torque_axes = np.empty((n, len(self.t_pu)))
        for i in range(n):
            vehicle = self.powertrain(c, s, i)
            params[i] = pack_parameters(vehicle, self.settings, 0.0)
            ep = vehicle.electric_powertrain
            r = np.asarray(ep.gear_ratios, float) * (ep.axle_ratio or vehicle.axle_ratio or 1.0)  # as simulate_cycle
            ratios[i, :len(r)], n_ratios[i] = r, len(r)
            speed_axes[i], torque_axes[i], _ = self.machine_map(s, i)
        metrics = np.zeros((n, len(self.batch.names), DK.n_metrics(len(self.window_steps))))
        f_roll, f_climb, mass = self.batch.road_rows(self.vehicle, self.mass_delta_kg(s))
        a = self.batch.args
        DK.simulate_batch(*a[:7], f_roll, f_climb, mass, *a[7:], params, ratios, n_ratios, speed_axes, torque_axes,
                          self.map_eff, self.settings.speed_tolerance_mps, self.window_steps, metrics)
        self.evaluated += n
        return metrics

    def evaluate(self, x) -> Evaluation:
        c = self.decode(x)
        s = C.size(c, self.voltage_v, self.resistance)
        m = self.simulate(c, s)
        return self.judge(c, s, m)

    def judge(self, c: C.Candidates, s: C.Sizing, m: np.ndarray) -> Evaluation:
        o, t, r = self.options, self.targets, self.vehicle.wheel_radius_m
        stalled = np.any(m[:, :, DK.M_STALLED] > 0, axis=1)
        m = np.nan_to_num(m)
        energy = np.nansum(m[:, self.in_consumption, DK.M_ENERGY_J], axis=1)
        distance = np.nansum(m[:, self.in_consumption, DK.M_DISTANCE_M], axis=1)
        kwh_per_km = np.where(distance > 0, energy / 3.6e6 / np.maximum(distance / 1000.0, 1e-9), np.inf)
        kwh_per_km = np.where(stalled, np.inf, kwh_per_km)
        g = np.zeros((len(c), len(constraint_names(o))))
        force = lambda v: C.wheel_force_limit_n(v, s, r)[:, 0]  # noqa: E731
        g[:, 0] = t["design_grade_force_n"] / np.maximum(force(o.design_grade_speed_mps), 1.0) - 1.0
        g[:, 1] = t["startability_force_n"] / np.maximum(force(0.0), 1.0) - 1.0
        g[:, 2] = t["top_speed_force_n"] / np.maximum(force(o.legal_top_speed_mps), 1.0) - 1.0
        usable_j = c.battery_energy_j * o.usable_soc_window * (1.0 - o.ageing_reserve)
        daily_j = kwh_per_km * 3.6e6 * self.energy_margin * self.daily_distance_m / 1000.0
        break_j = o.break_charging_s * o.break_charger_power_w
        g[:, 3] = np.where(np.isfinite(daily_j), (daily_j - break_j) / usable_j - 1.0, 10.0)
        peak_battery = np.nanmax(m[:, :, DK.M_PEAK_BATTERY_W], axis=1)
        g[:, 4] = peak_battery / s.battery_peak_power_w - 1.0
        loss = np.where(self.time_based[None, :],
                        1.0 - m[:, :, DK.M_DISTANCE_M] / np.maximum(self.free_distance_m[None, :], 1e-9),
                        m[:, :, DK.M_DURATION_S] / self.free_duration_s[None, :] - 1.0)
        g[:, 5] = np.where(stalled, 10.0, loss.max(axis=1) / MAX_TIME_LOSS - 1.0)
        n_w = len(o.thermal_windows_s)
        for k, w in enumerate(o.thermal_windows_s):
            overload = 1.0 / math.sqrt(1.0 - math.exp(-w / o.thermal_time_constant_s))
            t_adm = np.minimum(PEAK_TOLERANCE * s.peak_torque_nm, s.continuous_torque_nm * overload)
            p_adm = np.minimum(PEAK_TOLERANCE * s.peak_power_w, s.continuous_power_w * overload)
            rms = np.nanmax(m[:, :, DK.M_WINDOWS + k], axis=1)
            mean_p = np.nanmax(m[:, :, DK.M_WINDOWS + n_w + k], axis=1)
            g[:, len(CONSTRAINTS) + k] = np.where(stalled, 10.0, np.maximum(rms / t_adm, mean_p / p_adm) - 1.0)
        g = np.nan_to_num(g, nan=10.0, posinf=10.0)
        objectives = np.column_stack([np.nan_to_num(kwh_per_km, posinf=1e3), s.cost_eur])
        return Evaluation(c, s, objectives, g, m)
