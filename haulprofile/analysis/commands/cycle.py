"""``analyze cycle INPUT… --cycle-duration 1800 --candidates 100000 --seed 0 --out DIR``.

INPUT is a signals table (CSV/Parquet) or logs. The pipeline runs up to the cycle stage; gradient
or mass columns the input already has are kept, missing ones are estimated by the gradient and
mass stages; ``--mass-kg`` gives a known constant total mass instead.
"""

from __future__ import annotations

import sys
from pathlib import Path

from .. import checks
from ..errors import UserError
from ..vehicle import load_vehicle

EXIT_UNTRUSTWORTHY_RESULT = 3


def add_arguments(parser) -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help="signals tables (CSV/Parquet) or MCAP logs")
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path, required=True, help="output directory")
    parser.add_argument("--cycle-duration", "--duration", dest="cycle_duration", type=float, default=1800.0,
                        help="cycle duration [s] (1800)")
    parser.add_argument("--speed-class-kmh", type=float, default=1.0, help="speed class width [km/h] (1)")
    parser.add_argument("--gradient-class-pct", type=float, default=0.5, help="gradient class width [%%] (0.5)")
    parser.add_argument("--mass-class-kg", type=float, default=100.0, help="mass class width [kg] (100)")
    parser.add_argument("--candidates", type=int, default=100_000, help="Monte Carlo candidates (100000, about 2-3 s)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (0); same seed, same cycle")
    parser.add_argument("--update-counts", action="store_true",
                        help="draw without replacement from the measured transitions (paper's matrix update)")
    parser.add_argument("--mass-kg", type=float, help="known constant total mass [kg] when the input has none")
    parser.add_argument("--vehicle", help="vehicle file (TOML) or example name, for the mass stage")
    parser.add_argument("--dem", type=Path, help="directory of SRTM tiles, for the gradient stage")
    parser.add_argument("--quiet", action="store_true", help="print only errors")


def run(args) -> int:
    if args.candidates < 1:
        raise UserError(f"--candidates must be at least 1, got {args.candidates}")
    checks.cycle_duration_s(args.cycle_duration)
    if args.seed < 0:
        raise UserError(f"--seed must be a non-negative integer, got {args.seed}")
    if args.mass_kg is not None and not args.mass_kg > 0:
        raise UserError(f"--mass-kg must be a positive mass in kg, got {args.mass_kg}")
    from ..gradient.stage import GradientOptions
    from ..markov.classes import ClassWidths
    from ..markov.stage import CycleOptions
    from ..mass.stage import MassOptions
    from ..pipeline import Options, RunContext, run as run_pipeline

    widths = ClassWidths(args.speed_class_kmh, args.gradient_class_pct, args.mass_class_kg)
    options = Options(gradient=GradientOptions(keep_existing=True),
                      mass=MassOptions(known_mass_kg=args.mass_kg, keep_existing=True),
                      cycle=CycleOptions(duration_s=args.cycle_duration, widths=widths, n_candidates=args.candidates,
                                         seed=args.seed, update_counts=args.update_counts))
    ctx = RunContext(inputs=list(args.inputs), out_dir=args.out,
                     vehicle=load_vehicle(args.vehicle) if args.vehicle else None, dem_dir=args.dem,
                     say=(lambda _msg: None) if args.quiet else print, options=options,
                     json_files={"cycle.json": lambda ctx: ctx.summary.get("cycle")})
    ctx = run_pipeline(ctx, until="cycle")
    if ctx.results.cycle is None:
        reasons = [f"{name}: {reason}" for name, reason in ctx.skipped.items()]
        if "mass" in ctx.skipped and ctx.vehicle is None:
            reasons = ["the input has no mass_kg: give --vehicle for the mass stage, or --mass-kg"]
        raise UserError("no cycle: " + "; ".join(reasons))
    if not ctx.summary["cycle"]["valid"]:
        print(f"analyze cycle: warning: no valid cycle: {ctx.summary['cycle'].get('statement', '')} "
              f"(try more --candidates or a longer --cycle-duration)", file=sys.stderr)
        return EXIT_UNTRUSTWORTHY_RESULT
    return 0
