"""The design stage of `analyze run` (after simulate): requirements and a concept search on the
selected cycle set, the measured drive's requirements beside them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import UserError
from ..signals import missing_for
from ..simulate.cycle import SimCycle, default_mass_kg, read_cycle
from ..stage import Stage
from .chapter import TITLE, design_chapter, machines_text
from .evaluate import cycle_distance_m
from .options import DesignOptions
from .result import FILES, FOLDER, DesignResult, write_into

NEEDED = ["time_s", "speed_mps", "accel_mps2", "gradient_pct"]
MIN_DISTANCE_M = 100.0
"""A cycle shorter than this asks nothing of a powertrain (a truck that stood still): left out."""


def mass_sigma_kg(mass_summary: dict | None) -> float:
    """Standard deviation [kg] of the mass: the largest of the confident segments' (conservative,
    since a cycle mixes segments); 0 without a mass result."""
    if not mass_summary:
        return 0.0
    sigmas = [s.get("mass_uncertainty_kg") for s in mass_summary.get("segments", []) if s.get("mass_kg") is not None]
    sigmas = [s for s in sigmas if s is not None and np.isfinite(s)]
    return float(max(sigmas)) if sigmas else 0.0


def measured_drive(signals: pd.DataFrame | None, fallback_mass_kg: float) -> pd.DataFrame | None:
    """The measured drive's columns the requirements read, gaps left out, mass filled."""
    if signals is None or missing_for(signals, NEEDED):
        return None
    frame = signals[[c for c in NEEDED + ["mass_kg"] if c in signals.columns]].copy()
    mass = frame["mass_kg"].ffill().bfill() if "mass_kg" in frame else pd.Series(np.nan, index=frame.index)
    frame["mass_kg"] = mass.fillna(fallback_mass_kg)
    frame = frame.dropna(subset=NEEDED)
    return frame if len(frame) > 10 else None


def cycle_set(ctx, cycle_file=None) -> list[SimCycle]:
    """The cycles to design on: a cycle file, else every selection of the cycle stage, else the
    simulate stage's cycle (the measured drive)."""
    from ..simulate.stage import selected_cycle

    if cycle_file is not None:
        return [read_cycle(cycle_file, ctx.vehicle)]
    cycle = ctx.results.cycle
    if cycle is not None:
        chosen = cycle.selections or [cycle.selection]
        return [selected_cycle(s.cycle, f"generated cycle {k + 1}" if len(chosen) > 1 else "generated cycle")
                for k, s in enumerate(chosen) if {"distance_m", "mass_kg"} <= set(s.cycle.columns)]
    if ctx.signals is not None and not missing_for(ctx.signals, ["time_s", "speed_mps"]):
        from ..simulate.stage import SimulateOptions, measured_cycle

        measured = measured_cycle(ctx, getattr(ctx.options, "simulation", SimulateOptions()))
        return [measured] if measured is not None else []
    return []


def design_stage(ctx) -> DesignResult | None:
    """Requirements and concepts: the `DesignResult` (the pipeline keeps it in ``ctx.results.design``
    and its summary in ``ctx.summary["design"]``), or None when skipped.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``signals`` (time_s, speed_mps, accel_mps2, gradient_pct, mass_kg), ``vehicle``,
        ``results.mass`` / ``summary["mass"]`` (the mass uncertainty), ``results.cycle`` (the cycle set),
        ``summary["loads"]`` and ``options.design`` (`DesignOptions`).
    """
    from .synthesis import design_concepts

    options: DesignOptions = ctx.options.design
    if ctx.vehicle is None:
        ctx.skip("design", "no vehicle file")
        return None
    cycles = [c for c in cycle_set(ctx) if cycle_distance_m(c) >= MIN_DISTANCE_M]
    if not cycles:
        ctx.skip("design", f"no selected cycle and no drive of at least {MIN_DISTANCE_M:.0f} m to design on")
        return None
    measured = measured_drive(ctx.signals, default_mass_kg(ctx.vehicle))
    if measured is not None and float(np.sum(np.diff(measured["time_s"]) * measured["speed_mps"].iloc[1:])) < MIN_DISTANCE_M:
        measured = None
    sigma = mass_sigma_kg(ctx.summary.get("mass"))
    try:
        result: DesignResult = design_concepts(cycles, ctx.vehicle, options, measured, sigma, ctx.summary.get("loads"))
    except UserError as exc:
        ctx.skip("design", str(exc))
        return None
    summary = result.summary()
    c = summary["concept"]
    if c is None:
        ctx.say(f"design: no feasible concept; binding constraint: {summary['binding_constraint']}")
    else:
        ctx.say(f"design: {c['topology']}, {machines_text(c)}, "
                f"{c['gears']} gear(s), {c['battery_energy_kwh']:.0f} kWh, {c['battery_kwh_per_km']:.3f} kWh/km "
                f"({summary['candidates']} candidates in {result.search_s:.0f} s)")
    return result


def write_design_files(result: DesignResult, directory: Path, figures: bool = True) -> list[str]:
    """The design's files in ``directory`` (the run's ``design/``); returns the names."""
    return write_into(result, directory, figures)


STAGE = Stage("design", DesignOptions, design_stage, write=write_design_files, files=FILES, folder=FOLDER,
              chapter=design_chapter, title=TITLE, reads_vehicle=True, needs_signals=False)
