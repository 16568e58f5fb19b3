"""``analyze fleet LOGDIR… --vehicle FILE [--vehicle FILE…] --out DIR``: many logs, one cycle per
vehicle group (docs/fleet.md).

Exit codes: 0 done; 2 bad input (one line says which and what to do), including every log
failing; 3 done, but some logs failed or a group has no valid cycle (one line each on stderr);
1 an internal error (rerun with ``analyze --debug fleet …``); 130 interrupted.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .. import checks, jsonable
from ..fleet import FleetSpec, run_fleet
from ..gradient.stage import GradientOptions
from ..ingest.stage import IngestOptions
from ..mass.stage import MassOptions
from ..pipeline import Options
from ..vehicle import load_vehicle
from .arguments import (add_dem, add_known_road_and_mass, add_out, add_rate, check_mass_kg, parse_fleet_known_masses,
                        printer)

EXIT_INCOMPLETE = 3


def add_arguments(parser) -> None:
    parser.add_argument("log_dirs", nargs="+", type=Path, metavar="LOGDIR",
                        help="a directory of logs (MCAP, CAN logs or signals tables) per vehicle group")
    parser.add_argument("--vehicle", action="append", required=True,
                        help="vehicle file (TOML) or shipped example name; once for all groups or once per LOGDIR")
    add_dem(parser, "covering every route")
    add_out(parser)
    parser.add_argument("--workers", type=int, help="local worker processes (default: the CPU count; 1 = serial)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on an existing Dask distributed cluster, e.g. tcp://host:8786")
    parser.add_argument("--cycle-duration", "--duration", dest="cycle_duration", type=float, default=1800.0,
                        help="generated cycle length per group [s] (1800)")
    parser.add_argument("--candidates", type=int, default=None,
                        help="Monte Carlo pool of each group's refined cycle selection (20000, as analyze run)")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the cycle generation (0)")
    add_rate(parser)
    parser.add_argument("--known-mass", action="append", metavar="TRUCK:LOG:SEGMENT=KG",
                        help="a weighed total mass [kg] of one segment of one log (LOG: its file name or path under "
                             "LOGDIR, TRUCK: the LOGDIR's name): calibrates that truck's torque gain for all its logs")
    add_known_road_and_mass(parser)
    parser.add_argument("--no-figures", action="store_true",
                        help="skip each log's gradient and mass figures (some 30 %% of the time per log)")
    output = parser.add_mutually_exclusive_group()
    output.add_argument("--quiet", action="store_true", help="print only errors and warnings")
    output.add_argument("--json", action="store_true", help="print the fleet summary as JSON on stdout")


def run(args) -> int:
    checks.output_dir(args.out, args.log_dirs)
    checks.rate_hz(args.rate_hz)
    checks.cycle_duration_s(args.cycle_duration)
    check_mass_kg(args.mass_kg)
    vehicles = [load_vehicle(v) for v in args.vehicle]
    spec = FleetSpec.of(args.log_dirs, vehicles, dem_dir=args.dem, duration_s=args.cycle_duration,
                        n_candidates=args.candidates, seed=args.seed,
                        options=Options(ingest=IngestOptions(rate_hz=args.rate_hz),
                                        gradient=GradientOptions(flat_road=args.flat_road),
                                        mass=MassOptions(known_mass_kg=args.mass_kg)),
                        figures=not args.no_figures, known_masses=parse_fleet_known_masses(args.known_mass))
    quiet = args.quiet or args.json
    fleet = run_fleet(spec, args.out, workers=args.workers, scheduler=args.scheduler,
                      say=printer(quiet), debug=getattr(args, "debug", False),
                      progress=not quiet and sys.stderr.isatty())
    problems = []
    for group in fleet.groups:
        problems += [f"{group.name}: log {log} failed: {error}" for log, error in group.failed]
        if group.error:
            problems.append(f"{group.name}: no cycle: {group.error}")
        if "error" in group.road_load:
            problems.append(f"{group.name}: no shared road load: {group.road_load['error']}")
        elif group.selection and not group.selection.get("valid", True):
            problems.append(f"{group.name}: no valid cycle: {group.selection['statement']} (try more --candidates "
                            f"or a longer --cycle-duration)")
    if args.json:
        print(jsonable.dumps(json.loads((args.out / "fleet-summary.json").read_text())))
    for problem in problems:
        print(f"analyze fleet: warning: {problem}", file=sys.stderr)
    return EXIT_INCOMPLETE if problems else 0
