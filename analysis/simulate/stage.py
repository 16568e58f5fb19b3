"""The simulate stage: the electric truck on the selected cycle (or the measured drive, or a
cycle file), in memory (`SimulationResult`); `write_simulation` is its part of the output step,
`simulation_chapter` its report chapter."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..markov.export import cycle_to_vdri
from ..signals import missing_for
from ..stage import Stage
from .chapter import TITLE, simulation_chapter
from .cycle import SimCycle, SimulationInputError, default_mass_kg, distance_cycle, read_cycle, time_cycle
from .model import DriverSettings, SimulationResult, simulate_cycle
from .output import FILES, write_outputs

MIN_DISTANCE_KM = 0.1
"""Below this a drive gives no meaningful energy per km: the simulation is skipped, saying so."""
MEASURED_KEYS = ("cycle", "distance_km", "duration_s", "mean_mass_kg", "battery_kwh_per_km",
                 "wheel_positive_kwh_per_km", "recuperated_at_wheel_kwh", "missed_target_s")
"""What ``summary["simulation"]["measured_drive"]`` holds of the measured drive's simulation."""

Power = float | pd.DataFrame | tuple | None
"""A constant power [W], or a (time_s, power_w) series as a table or a pair of arrays."""


@dataclass(frozen=True)
class SimulateOptions:
    """Options of the simulate stage."""

    payload_kg: float | None = None
    """Payload [kg]; default half the vehicle's maximum payload (used where the cycle has no mass)."""
    aux_power_w: Power = None
    """Auxiliary power [W]; default the vehicle file's."""
    epto_power_w: Power = 0.0
    """Electric power take-off [W]."""
    obc_power_w: Power = 0.0
    """On-board charger power into the battery [W]."""
    driver: DriverSettings = field(default_factory=DriverSettings)
    """Integration step [s] and the driver model's settings."""
    cycle_file: Path | None = None
    """Simulate this cycle file (``.vdri``, or a time-based CSV/Parquet) instead of the selected
    cycle or the measured drive (``analyze simulate CYCLE``)."""


def selected_cycle(frame: pd.DataFrame, name: str = "generated cycle") -> SimCycle:
    """The cycle stage's 1 Hz cycle as the distance-based cycle its ``.vdri`` holds, with the
    cycle's mass [kg] at each row's distance."""
    vdri = cycle_to_vdri(frame)
    mass = frame["mass_kg"].ffill().bfill().to_numpy(float)
    return distance_cycle(vdri, np.interp(vdri["distance_m"].to_numpy(float), frame["distance_m"].to_numpy(float),
                                          mass), name)


def measured_cycle(ctx, options: SimulateOptions) -> SimCycle | None:
    """The measured drive as a time-based cycle, or None without time_s/speed_mps signals."""
    if ctx.signals is None or missing_for(ctx.signals, ["time_s", "speed_mps"]):
        return None
    columns = [c for c in ("time_s", "speed_mps", "gradient_pct", "mass_kg") if c in ctx.signals.columns]
    if missing_for(ctx.signals, ["gradient_pct"]):
        ctx.say("simulate: no gradient_pct in the signals, the measured drive is simulated as flat")
    return time_cycle(ctx.signals[columns], default_mass_kg(ctx.vehicle, options.payload_kg), "measured drive")


def cycle_for(ctx, options: SimulateOptions, measured: SimCycle | None = None) -> SimCycle | None:
    """What to simulate: the cycle file, else the selected cycle, else the measured drive."""
    vehicle = ctx.vehicle
    if options.cycle_file is not None:
        return read_cycle(options.cycle_file, vehicle, options.payload_kg)
    if ctx.results.cycle is not None:
        frame = ctx.results.cycle.frame
        if {"distance_m", "mass_kg"} <= set(frame.columns) and frame["mass_kg"].notna().any():
            return selected_cycle(frame)
        return distance_cycle(cycle_to_vdri(frame), default_mass_kg(vehicle, options.payload_kg), "generated cycle")
    return measured


def simulate_stage(ctx) -> SimulationResult | None:
    """Simulate the vehicle's electric powertrain into ``ctx.results.simulation`` and
    ``ctx.summary["simulation"]``; on the selected cycle, the measured drive is simulated beside it
    (``summary["simulation"]["measured_drive"]``). Why it was skipped goes to
    ``summary["skipped"]["simulation"]``.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``results.cycle`` (the selected cycle) or ``signals`` (time_s [s], speed_mps [m/s],
        gradient_pct [%], mass_kg [kg]), ``vehicle`` (its ``[electric_powertrain]``) and
        ``options.simulation`` (`SimulateOptions`).

    References
    ----------
    physics.md, simulation section: the road forces (2)-(3) of the one vehicle model.
    """
    options: SimulateOptions = ctx.options.simulation
    vehicle = ctx.vehicle
    if options.cycle_file is None and (vehicle is None or vehicle.electric_powertrain is None):
        return _skip(ctx, "the vehicle file has no [electric_powertrain] table")
    measured = measured_cycle(ctx, options) if options.cycle_file is None else None
    cycle = cycle_for(ctx, options, measured)
    if cycle is None:
        return _skip(ctx, "no selected cycle and no time_s/speed_mps signals")

    def run(on: SimCycle):
        return simulate_cycle(on, vehicle, aux_power_w=options.aux_power_w, epto_power_w=options.epto_power_w,
                              obc_power_w=options.obc_power_w, settings=options.driver)

    try:
        result = run(cycle)
    except SimulationInputError as exc:
        if options.cycle_file is not None:
            raise
        return _skip(ctx, str(exc))
    if options.cycle_file is None and not result.numbers["distance_km"] >= MIN_DISTANCE_KM:
        return _skip(ctx, f"the {cycle.name} covers {result.numbers['distance_km']:.2f} km (the truck hardly "
                          f"moved): no energy per km to give")
    if measured is not None and cycle is not measured:
        try:
            drive = run(measured).numbers
        except SimulationInputError as exc:
            ctx.say(f"simulation: measured drive not simulated, {exc}")
        else:
            if drive["distance_km"] >= MIN_DISTANCE_KM:
                result.numbers["measured_drive"] = {key: drive[key] for key in MEASURED_KEYS}
    ctx.say(f"simulation: {result.numbers['cycle']}, {result.numbers['battery_kwh_per_km']:.3f} kWh/km at the "
            f"battery, {result.numbers['missed_target_long_intervals']} interval(s) of "
            f"{result.numbers['missed_target_long_min_s']:g} s or more below target")
    return result


def _skip(ctx, reason: str) -> None:
    ctx.skip("simulation", reason)


def write_simulation(result: SimulationResult, directory: Path, figures: bool = True) -> list[str]:
    """The trace, numbers, residence and misses and, with ``figures``, the figures; returns the names."""
    return [path.name for path in write_outputs(result, directory, figures)]


STAGE = Stage("simulation", SimulateOptions, simulate_stage, write=write_simulation, files=FILES,
              folder="simulation", chapter=simulation_chapter, title=TITLE, reads_vehicle=True, needs_signals=False)
