"""``analyze design OUT_OF_RUN_OR_CYCLE --vehicle FILE [--out DIR]``: requirements and e-powertrain concepts."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from .. import checks, jsonable
from ..errors import UserError
from ..vehicle import load_vehicle
from .arguments import add_ownership

SUMMARY = "design-summary.json"
REPORT = "design-report.html"


def add_arguments(parser) -> None:
    from ..design.options import DesignOptions

    parser.add_argument("source", type=Path,
                        help="an 'analyze run' output folder (signals.parquet, cycle.parquet, summary.json), a VECTO "
                             ".vdri or a time-based CSV/Parquet (time_s, speed_mps[, gradient_pct, mass_kg])")
    parser.add_argument("--vehicle", required=True, help="vehicle file (TOML) or a shipped example name")
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path, default=Path("design-out"),
                        help="output directory (gets design/, design-summary.json, design-report.html)")
    parser.add_argument("--payload-kg", type=float, help="payload [kg] for cycles without mass_kg "
                                                         "(default: half the vehicle's max payload)")
    parser.add_argument("--daily-distance-km", type=float, help="distance a day [km] (default: the drive's)")
    parser.add_argument("--design-grade-pct", type=float, default=8.0, help="grade to climb at 30 km/h, gross mass")
    parser.add_argument("--startability-grade-pct", type=float, default=15.0, help="grade to start on, gross mass")
    parser.add_argument("--top-speed-kmh", type=float, default=90.0, help="legal top speed [km/h]")
    parser.add_argument("--usable-soc-window", type=float, default=0.9, help="usable share of the battery (0.9)")
    parser.add_argument("--ageing-reserve", type=float, default=0.2,
                        help="share of usable energy kept for end-of-life capacity fade (0.2)")
    parser.add_argument("--break-charging", nargs=2, type=float, metavar=("MINUTES", "KW"),
                        help="charging during the driver's breaks each day: minutes and charger power [kW]")
    parser.add_argument("--topology", nargs="+", choices=["central", "e-axle"], default=["central", "e-axle"])
    parser.add_argument("--max-machines", type=int, choices=[1, 2], default=2)
    parser.add_argument("--machine-power-kw", nargs=2, type=float, metavar=("MIN", "MAX"), default=[80.0, 450.0],
                        help="peak power range of one machine [kW]")
    parser.add_argument("--battery-kwh", nargs=2, type=float, metavar=("MIN", "MAX"), default=[100.0, 1000.0],
                        help="battery energy range [kWh]")
    parser.add_argument("--population", type=int, default=DesignOptions.population, help="NSGA-II population")
    parser.add_argument("--generations", type=int, default=DesignOptions.generations, help="NSGA-II generations")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cycle-only", action="store_true",
                        help="simulate the candidates on the cycle alone, not on the run's measured drive too "
                             "(faster; the concept then follows whatever the generated cycle holds)")
    parser.add_argument("--choice", choices=["ownership", "knee"], default="ownership",
                        help="choose the concept by the least cost of ownership (components + energy over the "
                             "service life; default) or by the Pareto front's knee")
    add_ownership(parser)
    parser.add_argument("--weights", nargs=2, type=float, metavar=("ENERGY", "COST"),
                        help="choose the concept by these weights on the normalised objectives instead")
    parser.add_argument("--json", action="store_true", help="print the design summary as JSON")


def options_from(args):
    from ..design import DesignOptions

    breaks = args.break_charging or (0.0, 0.0)
    if args.break_charging and min(breaks) < 0:
        raise UserError("--break-charging: minutes and kW must not be negative")
    return DesignOptions(
        design_grade_pct=args.design_grade_pct, startability_grade_pct=args.startability_grade_pct,
        legal_top_speed_mps=args.top_speed_kmh / 3.6, usable_soc_window=args.usable_soc_window,
        ageing_reserve=args.ageing_reserve,
        daily_distance_m=None if args.daily_distance_km is None else args.daily_distance_km * 1000.0,
        break_charging_s=breaks[0] * 60.0, break_charger_power_w=breaks[1] * 1000.0,
        topologies=tuple(dict.fromkeys(args.topology)), max_machines=args.max_machines,
        machine_power_range_w=(args.machine_power_kw[0] * 1000.0, args.machine_power_kw[1] * 1000.0),
        battery_energy_range_j=(args.battery_kwh[0] * 3.6e6, args.battery_kwh[1] * 3.6e6),
        population=args.population, generations=args.generations, seed=args.seed,
        weights=tuple(args.weights) if args.weights else None, choice=args.choice,
        energy_price_eur_per_kwh=args.energy_price_eur_per_kwh, service_life_years=args.service_life_years,
        operating_days_per_year=args.operating_days, simulate_measured_drive=not args.cycle_only)


def inputs_of(source: Path, vehicle, payload_kg):
    """(cycles, measured drive, mass sigma [kg], loads summary, files read) of a run folder or a cycle file."""
    from ..design.stage import mass_sigma_kg, measured_drive
    from ..simulate.cycle import default_mass_kg, read_cycle
    from ..simulate.stage import selected_cycle

    if source.is_dir():
        cycle_file, signals_file, summary_file = (source / "cycle.parquet", source / "signals.parquet",
                                                  source / "summary.json")
        if not cycle_file.is_file() and not signals_file.is_file():
            raise UserError(f"{source}: not an 'analyze run' output folder (no cycle.parquet or signals.parquet)")
        import pandas as pd

        summary = json.loads(summary_file.read_text()) if summary_file.is_file() else {}
        signals = pd.read_parquet(signals_file) if signals_file.is_file() else None
        measured = measured_drive(signals, default_mass_kg(vehicle, payload_kg))
        if cycle_file.is_file():
            cycles = [selected_cycle(pd.read_parquet(cycle_file))]
        elif measured is not None:
            from ..simulate.cycle import time_cycle

            cycles = [time_cycle(measured, default_mass_kg(vehicle, payload_kg), "measured drive")]
        else:
            raise UserError(f"{signals_file}: lacks time_s, speed_mps, accel_mps2 or gradient_pct to design on")
        read = [p for p in (cycle_file, signals_file, summary_file) if p.is_file()]
        return cycles, measured, mass_sigma_kg(summary.get("mass")), summary.get("loads"), read
    return [read_cycle(source, vehicle, payload_kg)], None, 0.0, None, [source]


def run(args) -> int:
    from ..design import design_concepts, write_design
    from ..design.chapter import design_chapter, machines_text
    from ..report.html import render

    if args.payload_kg is not None:
        checks.non_negative(args.payload_kg, "--payload-kg", "kg")
    if not args.source.exists():
        raise UserError(f"{args.source} not found: give an 'analyze run' output folder or a cycle file")
    vehicle = load_vehicle(args.vehicle)
    options = options_from(args)
    cycles, measured, sigma, loads, read = inputs_of(args.source, vehicle, args.payload_kg)
    out = checks.output_dir(args.out, read, names=["design", SUMMARY, REPORT])
    result = design_concepts(cycles, vehicle, options, measured, sigma, loads)
    summary = result.summary()
    try:
        out.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".partial-", dir=out))
    except OSError as exc:
        raise UserError(f"cannot write into {out}: {exc.strerror}") from None
    try:
        summary["files"] = write_design(result, staging)
        (staging / SUMMARY).write_text(jsonable.dumps(summary, indent=2))
        lead = f"{', '.join(summary['cycles'])} on {vehicle.name}."
        (staging / REPORT).write_text(render("haulprofile design", lead, [design_chapter(summary, staging / "design")]),
                                      encoding="utf-8")
        for name in ("design", SUMMARY, REPORT):
            if (out / name).is_dir():
                shutil.rmtree(out / name)
            os.replace(staging / name, out / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    if args.json:
        print(jsonable.dumps(summary, indent=2))
    concept = summary["concept"]
    if concept is None:
        every = summary["excluded"]["broken_by_every_candidate"]
        also = f"; every candidate broke {', '.join(every)}" if len(every) > 1 else ""
        print(f"no feasible concept in the design space: the binding constraint is {summary['binding_constraint']}"
              f"{also} ({summary['candidates']} candidates); see {out / SUMMARY}")
        return 3
    if not args.json:
        print(f"{concept['topology']}, {machines_text(concept)} peak "
              f"({concept['total_peak_torque_nm']:.0f} Nm in all), {concept['gears']} gear(s) "
              f"{', '.join(f'{r:.2f}' for r in concept['total_ratios'])}, {concept['battery_energy_kwh']:.0f} kWh: "
              f"{concept['battery_kwh_per_km']:.3f} kWh/km, {concept['cost_eur'] / 1000:.0f} k EUR; "
              f"{summary['candidates']} candidates in {summary['search_s']:.1f} s")
        print(f"wrote {out / 'design'} ({out / 'design' / 'concept.toml'} is a vehicle file for 'analyze simulate')")
    return 0
