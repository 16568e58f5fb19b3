"""Longitudinal simulation of the target battery-electric truck (physics.md, simulation section).

Public: `simulate`, `read_cycle`, `distance_cycle`, `time_cycle`, `DriverSettings`, `stage`.
"""

from __future__ import annotations

from ..signals import missing_for
from ..vecto import read_vdri
from .cycle import SimCycle, SimulationInputError, default_mass_kg, distance_cycle, read_cycle, time_cycle
from .model import DriverSettings, SimulationResult, simulate

__all__ = ["DriverSettings", "SimCycle", "SimulationInputError", "SimulationResult", "default_mass_kg",
           "distance_cycle", "read_cycle", "simulate", "stage", "time_cycle"]


def stage(ctx) -> None:
    """Pipeline stage: simulate on ``cycle.vdri`` in the output directory if the cycle stage wrote
    one, else on the measured drive as a time-based cycle; outputs into ``simulation/``.
    ``ctx.options["simulate"]`` may set ``payload_kg``, ``aux_power_w``, ``epto_power_w``, ``obc_power_w``."""
    from .output import write_outputs

    vehicle = ctx.vehicle
    if vehicle is None or vehicle.electric_powertrain is None:
        ctx.say("simulate: skipped, the vehicle file has no [electric_powertrain] table")
        return
    mass = default_mass_kg(vehicle, ctx.options.get("simulate", {}).get("payload_kg"))
    vdri = ctx.out_dir / "cycle.vdri"
    if vdri.is_file():
        frame = read_vdri(vdri)
        cycle = distance_cycle(frame, _cycle_mass(ctx, frame, mass), "generated cycle")
    elif ctx.signals is not None and not missing_for(ctx.signals, ["time_s", "speed_mps"]):
        columns = [c for c in ("time_s", "speed_mps", "gradient_pct", "mass_kg") if c in ctx.signals.columns]
        cycle = time_cycle(ctx.signals[columns], mass, "measured drive")
        if missing_for(ctx.signals, ["gradient_pct"]):
            ctx.say("simulate: no gradient_pct in the signals, the measured drive is simulated as flat")
    else:
        ctx.say("simulate: skipped, no cycle.vdri and no time_s/speed_mps signals")
        return
    try:
        result = simulate(cycle, vehicle, aux_power_w=ctx.options.get("simulate", {}).get("aux_power_w"),
                          epto_power_w=ctx.options.get("simulate", {}).get("epto_power_w", 0.0),
                          obc_power_w=ctx.options.get("simulate", {}).get("obc_power_w", 0.0))
    except SimulationInputError as exc:
        ctx.say(f"simulate: skipped, {exc}")
        return
    write_outputs(result, ctx.out_dir / "simulation")
    ctx.summary["simulation"] = result.summary
    ctx.say(f"simulate: {result.summary['cycle']}, {result.summary['battery_kwh_per_km']:.3f} kWh/km at the "
            f"battery, {result.summary['missed_target_intervals']} interval(s) below target")


def _cycle_mass(ctx, vdri_frame, fallback_kg: float):
    """Mass [kg] per row of the generated cycle: its cycle.csv mass mapped by driven distance,
    else ``fallback_kg``."""
    import numpy as np
    import pandas as pd

    csv = ctx.out_dir / "cycle.csv"
    if csv.is_file():
        frame = pd.read_csv(csv)
        if {"time_s", "speed_mps", "mass_kg"} <= set(frame.columns) and frame["mass_kg"].notna().any():
            if "distance_m" in frame.columns:
                distance = frame["distance_m"].to_numpy(float)
            else:
                time, speed = frame["time_s"].to_numpy(float), frame["speed_mps"].to_numpy(float)
                distance = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(time))])
            mass = frame["mass_kg"].ffill().bfill().to_numpy(float)
            return np.interp(vdri_frame["distance_m"].to_numpy(float), distance, mass)
    return fallback_kg
