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


MIN_DISTANCE_KM = 0.1
"""Below this a drive gives no meaningful energy per km: the simulation is skipped, saying so."""
MEASURED_KEYS = ("cycle", "distance_km", "duration_s", "mean_mass_kg", "battery_kwh_per_km",
                 "wheel_positive_kwh_per_km", "recuperated_at_wheel_kwh", "missed_target_s")


def stage(ctx) -> None:
    """Pipeline stage: simulate on ``cycle.vdri`` in the output directory if the cycle stage wrote
    one (and on the measured drive beside it, ``summary["simulation"]["measured_drive"]``), else on
    the measured drive as a time-based cycle; outputs into ``simulation/``. Why it was skipped goes
    to ``summary["skipped"]["simulation"]``.
    ``ctx.options["simulate"]`` may set ``payload_kg``, ``aux_power_w``, ``epto_power_w``, ``obc_power_w``."""
    from .output import write_outputs

    vehicle = ctx.vehicle
    if vehicle is None or vehicle.electric_powertrain is None:
        return _skip(ctx, "the vehicle file has no [electric_powertrain] table")
    options = ctx.options.get("simulate", {})
    mass = default_mass_kg(vehicle, options.get("payload_kg"))
    measured = None
    if ctx.signals is not None and not missing_for(ctx.signals, ["time_s", "speed_mps"]):
        columns = [c for c in ("time_s", "speed_mps", "gradient_pct", "mass_kg") if c in ctx.signals.columns]
        measured = time_cycle(ctx.signals[columns], mass, "measured drive")
        if missing_for(ctx.signals, ["gradient_pct"]):
            ctx.say("simulate: no gradient_pct in the signals, the measured drive is simulated as flat")
    vdri = ctx.out_dir / "cycle.vdri"
    if vdri.is_file():
        frame = read_vdri(vdri)
        cycle = distance_cycle(frame, _cycle_mass(ctx, frame, mass), "generated cycle")
    elif measured is not None:
        cycle = measured
    else:
        return _skip(ctx, "no cycle.vdri and no time_s/speed_mps signals")

    def run(on):
        return simulate(on, vehicle, aux_power_w=options.get("aux_power_w"),
                        epto_power_w=options.get("epto_power_w", 0.0), obc_power_w=options.get("obc_power_w", 0.0))

    try:
        result = run(cycle)
    except SimulationInputError as exc:
        return _skip(ctx, str(exc))
    if not result.summary["distance_km"] >= MIN_DISTANCE_KM:
        return _skip(ctx, f"the {cycle.name} covers {result.summary['distance_km']:.2f} km (the truck hardly "
                          f"moved): no energy per km to give")
    if cycle is not measured and measured is not None:
        try:
            drive = run(measured).summary
        except SimulationInputError as exc:
            ctx.say(f"simulate: measured drive not simulated, {exc}")
        else:
            if drive["distance_km"] >= MIN_DISTANCE_KM:
                result.summary["measured_drive"] = {key: drive[key] for key in MEASURED_KEYS}
    write_outputs(result, ctx.out_dir / "simulation")
    ctx.summary["simulation"] = result.summary
    ctx.say(f"simulate: {result.summary['cycle']}, {result.summary['battery_kwh_per_km']:.3f} kWh/km at the "
            f"battery, {result.summary['missed_target_intervals']} interval(s) below target")


def _skip(ctx, reason: str) -> None:
    ctx.summary.setdefault("skipped", {})["simulation"] = reason
    ctx.say(f"simulate: skipped, {reason}")


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
