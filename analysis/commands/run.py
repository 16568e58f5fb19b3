"""``analyze run INPUT… --vehicle FILE [--dem DIR] --out DIR``: every stage, one report.

Exit codes: 0 done; 2 bad input (one line says which and what to do); 3 done, but a result did
not meet its criteria (no confident mass in any segment, or no valid cycle), said in one line;
1 an internal error (rerun with ``analyze --debug run …`` for the traceback); 130 interrupted.
"""

from __future__ import annotations

import sys
from pathlib import Path

from .. import checks, jsonable
from ..errors import UserError
from ..gradient import GradientSettings
from ..gradient.stage import GradientOptions
from ..ingest.stage import IngestOptions
from ..loads.bins import read_overrides
from ..loads.stage import LoadsOptions
from ..markov.stage import CycleOptions
from ..mass.stage import MassOptions
from ..outputs import OutputOptions
from ..pipeline import Options, RunContext, run as run_pipeline, verdict
from ..simulate.stage import SimulateOptions
from ..vehicle import load_vehicle
from .arguments import (add_cycle, add_dem, add_design_search, add_inputs, add_known_road_and_mass, add_out, add_rate,
                        add_vehicle, check_mass_kg, design_options, in_flags, parse_known_masses, printer)

EXIT_UNTRUSTWORTHY_RESULT = 3


def add_arguments(parser) -> None:
    add_inputs(parser)
    add_vehicle(parser)
    add_dem(parser)
    add_out(parser)
    add_rate(parser)
    parser.add_argument("--dbc", type=Path, help="a DBC file whose signals are decoded as further columns")
    add_cycle(parser)
    parser.add_argument("--payload-kg", type=float, help="payload of the simulated electric truck [kg]")
    add_design_search(parser)
    parser.add_argument("--no-cache", action="store_true", help="rerun every stage (default: reuse unchanged ones)")
    parser.add_argument("--known-mass", action="append", metavar="SEGMENT=KG",
                        help="a weighed total mass of one segment (numbered from 1, as printed; KG alone: the "
                             "first): calibrates the engine torque gain for every segment (repeatable)")
    add_known_road_and_mass(parser)
    parser.add_argument("--gradient-method", choices=("smoother", "paper"), default="smoother",
                        help="gradient_pct from the Kalman smoother (default) or the paper's fusion (8)")
    parser.add_argument("--load-bins", type=Path,
                        help="TOML file of load-collective bin edges (default: those of the vehicle class)")
    parser.add_argument("--private", action="store_true",
                        help="keep positions and wall-clock time out of signals.parquet and the report (they are "
                             "used in memory for the DEM; heights and gradients stay); no stage cache is written")
    output = parser.add_mutually_exclusive_group()
    output.add_argument("--quiet", action="store_true", help="print only errors")
    output.add_argument("--json", action="store_true", help="print the summary as JSON on stdout, nothing else")


def options_from(args) -> Options:
    return Options(ingest=IngestOptions(rate_hz=args.rate_hz, dbc=args.dbc),
                   gradient=GradientOptions(GradientSettings(gradient_method=args.gradient_method),
                                            flat_road=args.flat_road),
                   mass=MassOptions(weighed_masses_kg=tuple(parse_known_masses(args.known_mass).items()),
                                    known_mass_kg=args.mass_kg),
                   cycle=CycleOptions(duration_s=args.cycle_duration, n_candidates=args.candidates, seed=args.seed),
                   simulation=SimulateOptions(payload_kg=args.payload_kg),
                   loads=LoadsOptions(bin_overrides=read_overrides(args.load_bins) if args.load_bins else ()),
                   design=design_options(args),
                   output=OutputOptions(private=args.private))


def check_arguments(args) -> None:
    """Every value of ``analyze run`` that can be checked before reading anything."""
    checks.rate_hz(args.rate_hz)
    checks.cycle_duration_s(args.cycle_duration)
    check_mass_kg(args.mass_kg)
    if args.mass_kg is not None and args.known_mass:
        raise UserError("give either --mass-kg (the mass, not estimated) or --known-mass (a weighing that "
                        "calibrates the estimate), not both")
    if args.candidates is not None and args.candidates < 1:
        raise UserError(f"--candidates must be at least 1, got {args.candidates}")
    design_options(args)
    if args.payload_kg is not None:
        checks.non_negative(args.payload_kg, "--payload-kg", "kg")


def run(args) -> int:
    check_arguments(args)
    quiet = args.quiet or args.json
    ctx = RunContext(inputs=list(args.inputs), out_dir=args.out, vehicle=load_vehicle(args.vehicle),
                     dem_dir=args.dem, options=options_from(args), say=printer(quiet))
    run_pipeline(ctx, cache=not args.no_cache, progress=not quiet and sys.stderr.isatty())
    problem = verdict(ctx)
    if args.json:
        print(jsonable.dumps(ctx.summary))
    else:
        ctx.say(f"wrote {args.out / 'report.html'}, {args.out / 'signals.parquet'} and {args.out / 'summary.json'}")
    if problem:
        print(f"analyze run: warning: {in_flags(problem)}{_hint(ctx, args)}", file=sys.stderr)
        return EXIT_UNTRUSTWORTHY_RESULT
    return 0


def _hint(ctx, args) -> str:
    """What carries a log without the sensors for an estimate (a CAN-only recording) to a result."""
    flags = [flag for stage, flag, given in (("gradient", "--flat-road", args.flat_road),
                                             ("mass", "--mass-kg KG", args.mass_kg is not None))
             if stage in ctx.skipped and not given]
    return f"; without the sensors for an estimate, give {' and '.join(flags)}" if flags else ""
