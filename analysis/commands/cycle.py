"""``analyze cycle INPUT… --cycle-duration 1800 [--selection refined|paper] [--cycles N] --seed 0 --out DIR``.

INPUT is a signals table (CSV/Parquet) or logs. The pipeline runs up to the cycle stage; gradient
or mass columns the input already has are kept, missing ones are estimated by the gradient and
mass stages; ``--mass-kg`` gives a known constant total mass instead.
"""

from __future__ import annotations

import sys

from .. import checks
from ..errors import UserError
from ..vehicle import load_vehicle
from .arguments import add_cycle, add_dem, add_inputs, add_out, add_vehicle, in_flags, printer

EXIT_UNTRUSTWORTHY_RESULT = 3


def add_arguments(parser) -> None:
    from ..markov.classes import ClassWidths

    widths = ClassWidths()
    add_inputs(parser, "signals tables (CSV/Parquet) or MCAP logs")
    add_out(parser)
    add_cycle(parser)
    parser.add_argument("--speed-class-kmh", type=float, default=widths.speed_kmh,
                        help=f"speed class width [km/h] ({widths.speed_kmh:g})")
    parser.add_argument("--gradient-class-pct", type=float, default=widths.gradient_pct,
                        help=f"gradient class width [%%] ({widths.gradient_pct:g})")
    parser.add_argument("--mass-class-kg", type=float, default=widths.mass_kg,
                        help=f"mass class width [kg] ({widths.mass_kg:g})")
    parser.add_argument("--selection", choices=("refined", "paper"), default="refined",
                        help="refined: the best Monte Carlo walks improved towards the criteria (and the wheel "
                             "loads, with --vehicle); paper: the paper's Monte Carlo, best of --candidates")
    parser.add_argument("--cycles", type=int, default=1, help="number of representative cycles (1); more go to cycles/")
    parser.add_argument("--update-counts", action="store_true",
                        help="draw without replacement from the measured transitions (paper's matrix update)")
    parser.add_argument("--mass-kg", type=float, help="known constant total mass [kg] when the input has none")
    add_vehicle(parser, required=False, what="for the mass stage and the wheel-load criteria of the refined selection")
    add_dem(parser, "for the gradient stage")
    parser.add_argument("--quiet", action="store_true", help="print only errors")


def run(args) -> int:
    if args.candidates is not None and args.candidates < 1:
        raise UserError(f"--candidates must be at least 1, got {args.candidates}")
    checks.cycle_duration_s(args.cycle_duration)
    if args.cycles < 1:
        raise UserError(f"--cycles must be at least 1, got {args.cycles}")
    if args.cycles > 1 and args.selection == "paper":
        raise UserError("--cycles above 1 needs --selection refined (the paper's selection keeps one cycle)")
    if args.seed < 0:
        raise UserError(f"--seed must be a non-negative integer, got {args.seed}")
    if args.mass_kg is not None and not args.mass_kg > 0:
        raise UserError(f"--mass-kg must be a positive mass in kg, got {args.mass_kg}")
    from ..gradient.stage import GradientOptions
    from ..markov.classes import ClassWidths
    from ..markov.stage import CycleOptions
    from ..mass.stage import MassOptions
    from ..outputs import OutputOptions
    from ..pipeline import Options, RunContext, run as run_pipeline

    widths = ClassWidths(args.speed_class_kmh, args.gradient_class_pct, args.mass_class_kg)
    options = Options(gradient=GradientOptions(keep_existing=True),
                      mass=MassOptions(known_mass_kg=args.mass_kg, keep_existing=True),
                      cycle=CycleOptions(duration_s=args.cycle_duration, widths=widths, n_candidates=args.candidates,
                                         seed=args.seed, update_counts=args.update_counts,
                                         selection=args.selection, n_cycles=args.cycles),
                      output=OutputOptions(summary_files=("cycle",)))
    ctx = RunContext(inputs=list(args.inputs), out_dir=args.out,
                     vehicle=load_vehicle(args.vehicle) if args.vehicle else None, dem_dir=args.dem,
                     say=printer(args.quiet), options=options)
    ctx = run_pipeline(ctx, until="cycle")
    if ctx.results.cycle is None:
        reasons = [f"{name}: {reason}" for name, reason in ctx.skipped.items()]
        if "mass" in ctx.skipped and ctx.vehicle is None:
            reasons = ["the input has no mass_kg: give --vehicle for the mass stage, or --mass-kg"]
        raise UserError("no cycle: " + "; ".join(reasons))
    if (problem := ctx.results.cycle.problem()) is not None:
        print(f"analyze cycle: warning: {in_flags(problem)}", file=sys.stderr)
        return EXIT_UNTRUSTWORTHY_RESULT
    return 0
