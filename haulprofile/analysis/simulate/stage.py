"""The simulate stage: the electric truck on the selected cycle (or the measured drive, or a
cycle file), in memory (`SimulationResult`); `write_simulation` in `analysis.simulate.output` is
its part of the output step."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..markov.export import cycle_to_vdri
from ..signals import missing_for
from .cycle import SimCycle, SimulationInputError, default_mass_kg, distance_cycle, read_cycle, time_cycle
from .model import DriverSettings, simulate_cycle

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


def cycle_for(ctx, options: SimulateOptions) -> SimCycle | None:
    """What to simulate: the cycle file, else the selected cycle, else the measured drive."""
    vehicle = ctx.vehicle
    if options.cycle_file is not None:
        return read_cycle(options.cycle_file, vehicle, options.payload_kg)
    mass = default_mass_kg(vehicle, options.payload_kg)
    if ctx.results.cycle is not None:
        frame = ctx.results.cycle.frame
        if {"distance_m", "mass_kg"} <= set(frame.columns) and frame["mass_kg"].notna().any():
            return selected_cycle(frame)
        return distance_cycle(cycle_to_vdri(frame), mass, "generated cycle")
    if ctx.signals is not None and not missing_for(ctx.signals, ["time_s", "speed_mps"]):
        columns = [c for c in ("time_s", "speed_mps", "gradient_pct", "mass_kg") if c in ctx.signals.columns]
        if missing_for(ctx.signals, ["gradient_pct"]):
            ctx.say("simulate: no gradient_pct in the signals, the measured drive is simulated as flat")
        return time_cycle(ctx.signals[columns], mass, "measured drive")
    return None


def simulate_stage(ctx) -> None:
    """Simulate the vehicle's electric powertrain into ``ctx.results.simulation`` and
    ``ctx.summary["simulation"]``.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``results.cycle`` (the selected cycle) or ``signals`` (time_s [s], speed_mps [m/s],
        gradient_pct [%], mass_kg [kg]), ``vehicle`` (its ``[electric_powertrain]``) and
        ``options.simulate`` (`SimulateOptions`).

    References
    ----------
    physics.md, simulation section: the road forces (2)-(3) of the one vehicle model.
    """
    options: SimulateOptions = ctx.options.simulate
    vehicle = ctx.vehicle
    if options.cycle_file is None and (vehicle is None or vehicle.electric_powertrain is None):
        ctx.skip("simulate", "the vehicle file has no [electric_powertrain] table")
        return
    cycle = cycle_for(ctx, options)
    if cycle is None:
        ctx.skip("simulate", "no selected cycle and no time_s/speed_mps signals")
        return
    try:
        result = simulate_cycle(cycle, vehicle, aux_power_w=options.aux_power_w, epto_power_w=options.epto_power_w,
                                obc_power_w=options.obc_power_w, settings=options.driver)
    except SimulationInputError as exc:
        if options.cycle_file is not None:
            raise
        ctx.skip("simulate", str(exc))
        return
    ctx.results.simulation = result
    ctx.summary["simulation"] = result.summary
    ctx.say(f"simulate: {result.summary['cycle']}, {result.summary['battery_kwh_per_km']:.3f} kWh/km at the "
            f"battery, {result.summary['missed_target_intervals']} interval(s) below target")
