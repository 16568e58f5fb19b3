"""``analyze cycle INPUT… --duration 1800 [--selection refined|paper] [--cycles N] --seed 0 --out DIR``.

INPUT is a signals table (CSV/Parquet) or, when the ingest stage is installed, MCAP logs. Missing
gradient or mass columns are computed by the pipeline's own stages (kinematics, gradient, mass)
when installed; ``--mass-kg`` gives a known constant total mass instead.
"""

from __future__ import annotations

import json
from pathlib import Path

from .. import pipeline
from .. import signals as signals_table
from ..errors import UserError
from ..markov.classes import ClassWidths
from ..markov.stage import stage as cycle_stage
from ..vehicle import load_vehicle

PRODUCES = {"kinematics": "accel_mps2", "gradient": "gradient_pct", "mass": "mass_kg"}


def add_arguments(parser) -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help="signals tables (CSV/Parquet) or MCAP logs")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--duration", type=float, default=1800.0, help="cycle duration [s] (1800)")
    parser.add_argument("--speed-class-kmh", type=float, default=1.0, help="speed class width [km/h] (1)")
    parser.add_argument("--gradient-class-pct", type=float, default=0.5, help="gradient class width [%%] (0.5)")
    parser.add_argument("--mass-class-kg", type=float, default=100.0, help="mass class width [kg] (100)")
    parser.add_argument("--selection", choices=("refined", "paper"), default="refined",
                        help="refined: the best Monte Carlo walks improved towards the criteria (and the wheel "
                             "loads, with --vehicle); paper: the paper's Monte Carlo, best of --candidates")
    parser.add_argument("--candidates", type=int,
                        help="Monte Carlo candidates (paper: 100000, about 2-3 s; refined: its pool, 20000)")
    parser.add_argument("--cycles", type=int, default=1, help="number of representative cycles (1); more go to cycles/")
    parser.add_argument("--seed", type=int, default=0, help="random seed (0); same seed, same cycle")
    parser.add_argument("--update-counts", action="store_true",
                        help="draw without replacement from the measured transitions (paper's matrix update)")
    parser.add_argument("--mass-kg", type=float, help="known constant total mass [kg] when the input has none")
    parser.add_argument("--vehicle", help="vehicle file (TOML) or example name, for the mass stage and the "
                                          "wheel-load criteria of the refined selection")
    parser.add_argument("--dem", type=Path, help="directory of SRTM tiles, for the gradient stage")
    parser.add_argument("--quiet", action="store_true", help="print only errors")


def _prepare(ctx: pipeline.RunContext, mass_kg: float | None) -> None:
    """Signals with speed, gradient and mass: read, or ingest and estimate through the pipeline."""
    pipeline.load_inputs(ctx)
    stages = dict(pipeline.available_stages())
    if ctx.signals is None:
        if "ingest" not in stages:
            raise UserError("the inputs are logs but no ingest stage is installed; give a signals table")
        ctx.say("[ingest]")
        stages["ingest"](ctx)
    if mass_kg is not None:
        if not mass_kg > 0:
            raise UserError(f"--mass-kg must be a positive mass in kg, got {mass_kg}")
        ctx.signals["mass_kg"] = float(mass_kg)
    for name, column in PRODUCES.items():
        if not signals_table.missing_for(ctx.signals, [column]):
            continue
        if name not in stages:
            ctx.say(f"{column} missing and the {name} stage is not installed")
            continue
        if name == "mass" and ctx.vehicle is None:
            raise UserError("the input has no mass_kg: give --vehicle for the mass stage, or --mass-kg")
        ctx.say(f"[{name}]")
        stages[name](ctx)


def _plain(value):
    """JSON form of NumPy scalars and paths in the summary."""
    if hasattr(value, "item"):
        return value.item()
    return str(value)


def run(args) -> int:
    if args.candidates is not None and args.candidates < 1:
        raise UserError(f"--candidates must be at least 1, got {args.candidates}")
    if not args.duration >= 2:
        raise UserError(f"--duration must be at least 2 s, got {args.duration}")
    if args.seed < 0:
        raise UserError(f"--seed must be a non-negative integer, got {args.seed}")
    widths = ClassWidths(args.speed_class_kmh, args.gradient_class_pct, args.mass_class_kg)
    ctx = pipeline.RunContext(
        inputs=list(args.inputs), out_dir=args.out, vehicle=load_vehicle(args.vehicle) if args.vehicle else None,
        dem_dir=args.dem, say=(lambda _msg: None) if args.quiet else print,
        options={"cycle": {"duration_s": args.duration, "widths": widths, "n_candidates": args.candidates,
                           "seed": args.seed, "update_counts": args.update_counts, "selection": args.selection,
                           "n_cycles": args.cycles}})
    args.out.mkdir(parents=True, exist_ok=True)
    _prepare(ctx, args.mass_kg)
    cycle_stage(ctx)
    if "cycle" not in ctx.summary:
        raise UserError("no cycle: the signals lack " + ", ".join(
            signals_table.missing_for(ctx.signals, ["gradient_pct", "mass_kg"])) + " (see the messages above)")
    (args.out / "cycle.json").write_text(json.dumps(ctx.summary["cycle"], indent=2, default=_plain))
    return 0 if ctx.summary["cycle"]["valid"] else 1
