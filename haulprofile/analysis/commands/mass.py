"""``analyze mass INPUT… --vehicle FILE [--dem DIR]``: per-segment vehicle mass by LS, RLS and LM
beside the truck's own CAN estimate; a figure like the paper's Fig. 6."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .. import checks
from ..errors import UserError
from ..vehicle import load_vehicle

EXIT_UNTRUSTWORTHY_RESULT = 3


def add_arguments(parser) -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help="MCAP logs, directories of logs, or signals tables")
    parser.add_argument("--vehicle", required=True, help="vehicle file (TOML) or a shipped example name")
    parser.add_argument("--dem", type=Path, help="directory of SRTM .hgt tiles or GeoTIFFs (for the gradient)")
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path, default=Path("mass-out"),
                        help="output directory")
    parser.add_argument("--true-mass", type=float, nargs="+", metavar="KG",
                        help="the real total mass [kg], if weighed, for the figure: one value, or one per segment")
    parser.add_argument("--forgetting-factor", type=float, default=0.9985, help="lambda of RLS and LM (default 0.9985)")
    parser.add_argument("--no-figure", action="store_true", help="skip the figure")


def format_segments(segments: list[dict]) -> str:
    """The per-segment table printed by ``analyze mass``."""
    def kg(value):
        return f"{value:>8.0f}" if value is not None else f"{'-':>8}"

    lines = [f"{'segment [s]':>15} {'samples':>7} {'LS':>8} {'± [kg]':>7} {'RLS':>8} {'LM':>8} {'CAN':>8}  status"]
    for s in segments:
        uncertainty = f"{s['uncertainty_kg']:>7.0f}" if s["uncertainty_kg"] not in (None, np.inf) else f"{'-':>7}"
        lines.append(f"{s['start_s']:>7.0f}-{s['end_s']:<7.0f} {s['n_samples']:>7d} {kg(s['mass_ls_kg'])} {uncertainty} "
                     f"{kg(s['mass_rls_kg'])} {kg(s['mass_lm_kg'])} {kg(s['reported_mass_kg'])}  "
                     f"{s['status']}{': ' + s['reason'] if s['reason'] else ''}")
    return "\n".join(lines)


def _mass_json(ctx):
    return {"segments": ctx.summary["mass"]["segments"]} if ctx.results.mass is not None else None


def run(args) -> int:
    from ..gradient.stage import GradientOptions
    from ..mass import SegmentSettings
    from ..mass.stage import MassOptions
    from ..pipeline import Options, RunContext, run as run_pipeline

    checks.forgetting_factor(args.forgetting_factor)
    for mass in args.true_mass or []:
        checks.positive(mass, "--true-mass", "kg")
    options = Options(gradient=GradientOptions(keep_existing=True),
                      mass=MassOptions(segments=SegmentSettings(forgetting_factor=args.forgetting_factor),
                                       true_mass_kg=tuple(args.true_mass) if args.true_mass else None))
    ctx = RunContext(inputs=list(args.inputs), out_dir=args.out, vehicle=load_vehicle(args.vehicle),
                     dem_dir=args.dem, options=options, figures=not args.no_figure,
                     json_files={"mass.json": _mass_json})
    ctx = run_pipeline(ctx, until="mass")
    if ctx.results.mass is None:
        raise UserError(ctx.skipped.get("mass", "no mass estimated"))
    print(format_segments(ctx.results.mass.segments))
    print(f"wrote {args.out / 'mass.json'}")
    for name in ctx.summary["mass"]["files"]:
        print(f"wrote {args.out / name}")
    if not any(s["status"] == "ok" for s in ctx.results.mass.segments):
        print("analyze mass: warning: no segment has enough excitation for a confident mass", file=sys.stderr)
        return EXIT_UNTRUSTWORTHY_RESULT
    return 0
