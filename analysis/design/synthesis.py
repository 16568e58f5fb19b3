"""From drives and cycles to a concept: requirements, the search, the chosen concept, and the
vehicle file's own powertrain on the same cycles for comparison (`design_concepts`)."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import pandas as pd

from ..errors import UserError
from ..simulate.cycle import SimCycle, time_cycle
from ..simulate.model import DriverSettings, simulate_cycle
from ..vehicle import Vehicle
from . import components as C
from . import requirements as R
from .choice import CHOICES, criterion
from .evaluate import UNLIMITED, Evaluator, cycle_distance_m
from .options import DesignOptions
from .result import DesignResult
from .search import exclusions, run_search

def driven(cycle: SimCycle, vehicle: Vehicle, dt: float) -> pd.DataFrame:
    """A cycle as the simulator's driver drives it without powertrain limits: time_s, speed_mps,
    accel_mps2, gradient_pct, mass_kg per step."""
    trace = simulate_cycle(cycle, replace(vehicle, electric_powertrain=UNLIMITED),
                           settings=DriverSettings(time_step_s=dt)).trace
    where = trace["time_s"] if cycle.time_based else trace["distance_m"]
    mass = np.interp(where, cycle.position, cycle.mass_kg)
    return pd.DataFrame({"time_s": trace["time_s"], "speed_mps": trace["speed_mps"], "accel_mps2": trace["accel_mps2"],
                         "gradient_pct": trace["gradient_pct"], "mass_kg": mass})


def check_options(options: DesignOptions) -> None:
    """Targets a road truck can be designed for; else a one-line error naming the field."""
    if not 0.0 <= options.design_grade_pct <= 30.0:
        raise UserError(f"design_grade_pct {options.design_grade_pct:g} %: road grades for trucks end near 30 %; "
                        f"give 0..30")
    if not 0.0 <= options.startability_grade_pct <= 40.0:
        raise UserError(f"startability_grade_pct {options.startability_grade_pct:g} %: give 0..40")
    if not 5.0 <= options.legal_top_speed_mps <= 45.0:
        raise UserError(f"legal_top_speed_mps {options.legal_top_speed_mps:g} m/s is not a truck's top speed; "
                        f"give 5..45 m/s")
    if not 0.1 <= options.usable_soc_window <= 1.0 or not 0.0 <= options.ageing_reserve < 0.9:
        raise UserError("usable_soc_window must lie in 0.1..1 and ageing_reserve in 0..0.9")
    lo, hi = options.machine_power_range_w
    e_lo, e_hi = options.battery_energy_range_j
    if not (0 < lo <= hi) or not (0 < e_lo <= e_hi) or not options.topologies or options.max_machines < 1:
        raise UserError("the design space is empty: machine_power_range_w and battery_energy_range_j need "
                        "0 < low <= high, topologies at least one of central, e-axle, max_machines >= 1")
    unknown = set(options.topologies) - set(C.TOPOLOGIES)
    if unknown:
        raise UserError(f"topologies: unknown {', '.join(sorted(unknown))} (known: {', '.join(C.TOPOLOGIES)})")
    if options.population < 4 or options.generations < 1:
        raise UserError("population must be at least 4 and generations at least 1")
    if options.daily_distance_m is not None and options.daily_distance_m <= 0:
        raise UserError(f"daily_distance_m {options.daily_distance_m:g} must be positive")
    if options.choice not in CHOICES:
        raise UserError(f"choice {options.choice!r}: give one of {', '.join(CHOICES)}")
    if not 0.0 <= options.energy_price_eur_per_kwh <= 10.0:
        raise UserError(f"energy_price_eur_per_kwh {options.energy_price_eur_per_kwh:g}: give 0..10 EUR/kWh")
    if not 0.0 < options.service_life_years <= 50.0 or not 0.0 < options.operating_days_per_year <= 366.0:
        raise UserError(f"service_life_years {options.service_life_years:g} and operating_days_per_year "
                        f"{options.operating_days_per_year:g}: give 0 < years <= 50 and 0 < days <= 366")
    if not 0.0 <= options.near_optimal_share <= 1.0:
        raise UserError(f"near_optimal_share {options.near_optimal_share:g}: give 0..1")


MEASURED = "measured drive"
MEASURED_DRIVE_MAX_RATIO = 3.0
"""The measured drive joins the simulated set while it is at most this many times as long as the
cycles (distance): it costs its length per candidate, and a day-long log would make the search
tens of times longer than the cycle it was condensed into [choice; the demo's drive is 1.3 x].
A longer drive is represented by its hardest stretch of that length (`hardest_stretch`)."""
HARDEST = "hardest stretch of the measured drive"


def with_measured_drive(cycles: list[SimCycle], measured: pd.DataFrame | None, options: DesignOptions,
                        vehicle: Vehicle | None = None) -> list[SimCycle]:
    """The cycles, and the measured drive as a time-based cycle (``simulate_measured_drive``): a
    generated cycle is a random walk through the drive's statistics and may or may not hold its
    longest climbs, so a concept that only drives the cycle follows whichever the walk happened to
    hold; the drive itself is the application's real demand. A drive longer than
    `MEASURED_DRIVE_MAX_RATIO` times the cycles joins as its hardest stretch of that length (given
    the ``vehicle`` whose road load judges it), which sizes but does not count in the energy per km."""
    if measured is None or not options.simulate_measured_drive or any(c.name in (MEASURED, HARDEST) for c in cycles):
        return cycles
    drive = time_cycle(measured, float(measured["mass_kg"].mean()), MEASURED)
    longest_m = MEASURED_DRIVE_MAX_RATIO * sum(cycle_distance_m(c) for c in cycles)
    if cycle_distance_m(drive) <= longest_m:
        return [*cycles, drive]
    if vehicle is None:
        return cycles
    stretch = hardest_stretch(measured, vehicle, longest_m)
    return [*cycles, time_cycle(stretch, float(stretch["mass_kg"].mean()), HARDEST)]


def hardest_stretch(measured: pd.DataFrame, vehicle: Vehicle, length_m: float) -> pd.DataFrame:
    """The stretch of ``length_m`` of the measured drive that asks the most positive energy at the
    wheel (its longest climbs and hardest accelerations at their mass), starting from a standstill
    where one allows a whole stretch (a cycle starts at rest), its time from 0."""
    from ..road_load import wheel_force_n

    time_s = measured["time_s"].to_numpy(float)
    speed = np.clip(measured["speed_mps"].to_numpy(float), 0.0, None)
    step_s = np.diff(time_s, prepend=time_s[0])
    distance_m = np.cumsum(speed * step_s)
    force = wheel_force_n(speed, measured["accel_mps2"].to_numpy(float), measured["gradient_pct"].to_numpy(float),
                          measured["mass_kg"].to_numpy(float), vehicle)
    energy_j = np.cumsum(np.clip(force * speed, 0.0, None) * step_s)
    starts = np.flatnonzero(distance_m + length_m <= distance_m[-1])
    if not len(starts):
        return measured.assign(time_s=time_s - time_s[0])
    at_rest = starts[speed[starts] < 0.5]
    starts = at_rest if len(at_rest) else starts
    ends = np.minimum(np.searchsorted(distance_m, distance_m[starts] + length_m), len(distance_m) - 1)
    best = int(np.argmax(energy_j[ends] - energy_j[starts]))
    stretch = measured.iloc[starts[best]:ends[best] + 1]
    return stretch.assign(time_s=stretch["time_s"] - stretch["time_s"].iloc[0])


def design_concepts(cycles: list[SimCycle], vehicle: Vehicle, options: DesignOptions,
                    measured: pd.DataFrame | None = None, mass_sigma_kg: float = 0.0,
                    loads_summary: dict | None = None) -> DesignResult:
    """Requirements of ``measured`` (signals: time_s, speed_mps, accel_mps2, gradient_pct, mass_kg)
    and the ``cycles``, then the NSGA-II concept search on the cycles.

    Parameters
    ----------
    cycles : list of SimCycle
        The cycle set the candidates are simulated on (the cycle stage's selections or a cycle file).
    vehicle : Vehicle
        Road load (c_d, A, c_r, r_dyn), masses, and the reference ``[electric_powertrain]`` if any.
    options : DesignOptions
    measured : DataFrame, optional
        The measured drive, for its requirements; the candidates drive it too (`with_measured_drive`).
    mass_sigma_kg : float
        Standard deviation of the mass estimate [kg]; requirements at +-``options.mass_sigmas`` of it.
    loads_summary : dict, optional
        The loads stage's summary, whose damage-equivalent torques stand in the requirement table.
    """
    check_options(options)
    if not cycles:
        raise UserError("no cycle to design on: give a cycle file or a run with a selected cycle")
    cycles = with_measured_drive(cycles, measured, options, vehicle)
    sizing_only = frozenset(c.name for c in cycles if c.name == HARDEST)
    started = time.perf_counter()
    dt = options.time_step_s
    drives = {}
    if measured is not None:
        drives[MEASURED] = measured
    for cycle in cycles:
        if cycle.name not in drives and cycle.name not in sizing_only:  # the measured drive is there, as measured
            drives[cycle.name] = driven(cycle, vehicle, dt)
    rotating = vehicle.electric_powertrain.rotating_mass_kg if vehicle.electric_powertrain else 0.0
    ranges, per_drive = R.requirement_ranges(drives, vehicle, options, mass_sigma_kg, rotating)
    heaviest = max(float(d["mass_kg"].max()) for d in drives.values()) + options.mass_sigmas * mass_sigma_kg
    targets = R.static_requirements(vehicle, options, heaviest, ranges["max_gradient_pct"]["high"],
                                    options.design_grade_speed_mps)
    first = next(iter(per_drive))
    nominal = per_drive[first]["estimate"]["positive_wheel_kwh_per_km"]
    margin = ranges["positive_wheel_kwh_per_km"]["high"] / nominal if nominal and math.isfinite(nominal) else 1.0
    daily_m = options.daily_distance_m or 1000.0 * max(ranges["distance_km"]["value"], 1e-3)
    evaluator = Evaluator(vehicle, cycles, options, targets, daily_m, max(margin, 1.0), sizing_only)
    rule = criterion(options, daily_m)
    outcome = run_search(evaluator, rule)
    search_s = time.perf_counter() - started
    reference = _reference_powertrain(vehicle, cycles, dt, sizing_only)
    if reference is not None:
        reference["ownership_cost_eur"] = float(rule.ownership_eur([[reference["battery_kwh_per_km"], reference["cost_eur"]]])[0])
    return DesignResult(options=options, vehicle=vehicle, evaluator=evaluator, outcome=outcome, ranges=ranges,
                        per_drive=per_drive, targets=targets, daily_distance_m=daily_m, energy_margin=margin,
                        mass_sigma_kg=mass_sigma_kg, drives=drives,
                        exclusions=exclusions(outcome, _regions(outcome, evaluator)), reference=reference,
                        loads=loads_summary or {}, search_s=search_s)


def _regions(outcome, evaluator) -> list[str]:
    c = evaluator.decode(outcome.x)
    return [f"{C.TOPOLOGIES[t]}, {m} machine(s), {s} gear(s)" for t, m, s in zip(c.topology, c.machines, c.speeds)]


def _reference_powertrain(vehicle: Vehicle, cycles: list[SimCycle], dt: float,
                          sizing_only: frozenset[str] = frozenset()) -> dict | None:
    """The vehicle file's own powertrain on the same cycles (energy per km without the
    ``sizing_only`` ones, time below target on all)."""
    ep = vehicle.electric_powertrain
    if ep is None:
        return None
    energy = distance = missed = 0.0
    for cycle in cycles:
        s = simulate_cycle(cycle, vehicle, settings=DriverSettings(time_step_s=dt)).numbers
        if cycle.name not in sizing_only:
            energy += s["battery_terminal_energy_kwh"]
            distance += s["distance_km"]
        missed += s["missed_target_s"]
    kw = ep.machine_max_power_w / 1000.0
    kwh = ep.battery_capacity_kwh
    return {"machine_peak_power_w": ep.machine_max_power_w, "machine_peak_torque_nm": ep.machine_max_torque_nm,
            "machine_max_speed_rpm": ep.machine_max_speed_rpm, "gear_ratios": list(ep.gear_ratios),
            "axle_ratio": ep.axle_ratio or vehicle.axle_ratio, "battery_energy_kwh": kwh,
            "battery_kwh_per_km": energy / distance if distance > 0 else math.nan, "missed_target_s": missed,
            "cost_eur": C.EUR_PER_MACHINE + C.EUR_PER_KW_MACHINE * kw + C.EUR_PER_KVA_INVERTER * kw / C.POWER_FACTOR
            + C.EUR_GEARBOX_BASE + C.EUR_PER_GEAR * len(ep.gear_ratios) + C.EUR_PER_KWH_BATTERY * kwh}
