"""``analyze mass INPUT… --vehicle FILE [--dem DIR]``: per-segment vehicle mass by LS, RLS and LM
beside the truck's own CAN estimate; a figure like the paper's Fig. 6."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..vehicle import load_vehicle
from .gradient import signals_for


def add_arguments(parser) -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help="MCAP logs, directories of logs, or signals tables")
    parser.add_argument("--vehicle", required=True, help="vehicle file (TOML) or a shipped example name")
    parser.add_argument("--dem", type=Path, help="directory of SRTM .hgt tiles or GeoTIFFs (for the gradient)")
    parser.add_argument("--out", type=Path, default=Path("mass-out"), help="output directory")
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
    from ..gradient import stage as gradient_stage
    from ..mass import SegmentSettings, estimate_mass
    from ..mass.calibration import parse_known_masses
    from ..mass.figure import draw_estimates

    vehicle = load_vehicle(args.vehicle)
    ctx = signals_for(args.inputs, print, args.out, vehicle=vehicle, dem_dir=args.dem,
                      options={"gradient": {"method": args.gradient_method}})
    if "gradient_pct" not in ctx.signals.columns:
        gradient_stage(ctx)
    result = estimate_mass(ctx.signals, vehicle, segment_settings=SegmentSettings(forgetting_factor=args.forgetting_factor),
                           known_masses=parse_known_masses(args.known_mass))
    for note in result.notes:
        print(f"note: {note}")
    print(format_segments(result.segments))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "mass.json").write_text(json.dumps({"segments": result.segments, "road_load": result.road_load},
                                                   indent=2))
    print(f"wrote {args.out / 'mass.json'}")
    if not args.no_figure:
        print(f"wrote {draw_estimates(ctx.signals, result, args.out / 'mass.png', args.true_mass)}")
    return 0
