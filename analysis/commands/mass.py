"""``analyze mass INPUT… --vehicle FILE [--dem DIR]``: per-segment vehicle mass by LS, RLS and LM
beside the truck's own CAN estimate, and the joint estimate (all segments' masses with the drive's
c_r and c_d·A, calibrated by ``--known-mass``); a figure like the paper's Fig. 6."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .. import checks
from ..errors import UserError
from ..vehicle import load_vehicle
from .arguments import add_dem, add_inputs, add_out, add_vehicle, refuse_cycles

EXIT_UNTRUSTWORTHY_RESULT = 3


def add_arguments(parser) -> None:
    add_inputs(parser)
    add_vehicle(parser)
    add_dem(parser, "for the gradient")
    add_out(parser, Path("mass-out"))
    parser.add_argument("--true-mass", type=float, nargs="+", metavar="KG",
                        help="the real total mass [kg], if weighed, for the figure: one value, or one per segment")
    parser.add_argument("--forgetting-factor", type=float, default=0.9985, help="lambda of RLS and LM (default 0.9985)")
    parser.add_argument("--no-figure", action="store_true", help="skip the figure")
    parser.add_argument("--known-mass", action="append", metavar="SEGMENT=KG",
                        help="a weighed total mass of one segment (numbered from 1, as printed; KG alone: the "
                             "first): calibrates the engine torque gain for every segment (repeatable)")
    parser.add_argument("--gradient-method", choices=("smoother", "paper"), default="smoother",
                        help="gradient_pct from the Kalman smoother (default) or the paper's fusion (8)")


def format_segments(segments: list[dict]) -> str:
    """The per-segment table printed by ``analyze mass``."""
    def kg(value):
        return f"{value:>8.0f}" if value is not None else f"{'-':>8}"

    def pm(value):
        return f"{value:>7.0f}" if value not in (None, np.inf) else f"{'-':>7}"

    lines = [f"{'#':>2} {'segment [s]':>15} {'mass':>8} {'± [kg]':>7} {'from':>8} {'samples':>7} {'LS':>8} {'± [kg]':>7} "
             f"{'RLS':>8} {'LM':>8} {'CAN':>8}  status"]
    for number, s in enumerate(segments, 1):
        uncertainty = pm(s["uncertainty_kg"])
        lines.append(f"{number:>2} {s['start_s']:>7.0f}-{s['end_s']:<7.0f} {kg(s.get('mass_kg'))} "
                     f"{pm(s.get('mass_uncertainty_kg'))} {s.get('mass_regressor', ''):>8} "
                     f"{s['n_samples']:>7d} {kg(s['mass_ls_kg'])} {uncertainty} "
                     f"{kg(s['mass_rls_kg'])} {kg(s['mass_lm_kg'])} {kg(s['reported_mass_kg'])}  "
                     f"{s['status']}{': ' + s['reason'] if s['reason'] else ''}")
    return "\n".join(lines)


def run(args) -> int:
    refuse_cycles(args.inputs, "mass")
    from ..gradient.stage import GradientOptions
    from ..gradient import GradientSettings
    from ..mass import SegmentSettings
    from .arguments import parse_known_masses
    from ..mass.stage import MassOptions
    from ..outputs import OutputOptions
    from ..pipeline import Options, RunContext, run as run_pipeline

    checks.forgetting_factor(args.forgetting_factor)
    for mass in args.true_mass or []:
        checks.positive(mass, "--true-mass", "kg")
    weighed = tuple(parse_known_masses(args.known_mass).items())
    options = Options(gradient=GradientOptions(GradientSettings(gradient_method=args.gradient_method),
                                               keep_existing=True),
                      mass=MassOptions(segments=SegmentSettings(forgetting_factor=args.forgetting_factor),
                                       true_mass_kg=tuple(args.true_mass) if args.true_mass else None,
                                       weighed_masses_kg=weighed),
                      output=OutputOptions(figures=not args.no_figure, summary_files=("mass",)))
    ctx = RunContext(inputs=list(args.inputs), out_dir=args.out, vehicle=load_vehicle(args.vehicle),
                     dem_dir=args.dem, options=options)
    ctx = run_pipeline(ctx, until="mass")
    if ctx.results.mass is None:
        raise UserError(ctx.skipped.get("mass", "no mass estimated"))
    print(format_segments(ctx.results.mass.segments))
    print(f"wrote {args.out / 'mass.json'}")
    for name in ctx.summary["mass"]["files"]:
        print(f"wrote {args.out / name}")
    if not any("ok" in (s["status"], s.get("mass_joint_status")) for s in ctx.results.mass.segments):
        print("analyze mass: warning: no segment has enough excitation for a confident mass", file=sys.stderr)
        return EXIT_UNTRUSTWORTHY_RESULT
    return 0
