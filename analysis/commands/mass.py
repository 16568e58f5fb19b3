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


def run(args) -> int:
    from ..gradient import stage as gradient_stage
    from ..mass import SegmentSettings, estimate_mass

    vehicle = load_vehicle(args.vehicle)
    ctx = signals_for(args.inputs, print, vehicle=vehicle, dem_dir=args.dem)
    if "gradient_pct" not in ctx.signals.columns:
        gradient_stage(ctx)
    result = estimate_mass(ctx.signals, vehicle, segment_settings=SegmentSettings(forgetting_factor=args.forgetting_factor))
    for note in result.notes:
        print(f"note: {note}")
    print(format_segments(result.segments))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "mass.json").write_text(json.dumps({"segments": result.segments}, indent=2))
    print(f"wrote {args.out / 'mass.json'}")
    if not args.no_figure:
        print(f"wrote {draw_estimates(ctx.signals, result, args.out / 'mass.png', args.true_mass)}")
    return 0


def draw_estimates(frame, result, path: Path, true_mass_kg: list[float] | None = None) -> Path:
    """Paper Fig. 6: the estimates of each method over time, the CAN estimate and the real mass."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    time_s = frame["time_s"].to_numpy()
    fig, ax = plt.subplots(figsize=(10, 5))
    for column, label in (("mass_rls_kg", "RLS"), ("mass_lm_kg", "Levenberg-Marquardt"), ("mass_ls_kg", "LS per segment")):
        ax.plot(time_s, result.columns[column] / 1000, label=label, lw=1.5 if column == "mass_ls_kg" else 0.8)
    if "reported_mass_kg" in frame:
        ax.plot(time_s, frame["reported_mass_kg"] / 1000, ".", ms=1, label="vehicle CAN estimate")
    if true_mass_kg and len(true_mass_kg) == len(result.segments) > 1:
        for k, (segment, mass) in enumerate(zip(result.segments, true_mass_kg)):
            ax.plot([segment["start_s"], segment["end_s"]], [mass / 1000] * 2, "k--", label="real mass" if k == 0 else None)
    elif true_mass_kg:
        ax.axhline(true_mass_kg[0] / 1000, color="k", ls="--", label="real mass")
    for segment in result.segments:
        if segment["uncertainty_kg"] not in (None, np.inf) and segment["mass_ls_kg"] is not None:
            ax.fill_between([segment["start_s"], segment["end_s"]],
                            (segment["mass_ls_kg"] - 2 * segment["uncertainty_kg"]) / 1000,
                            (segment["mass_ls_kg"] + 2 * segment["uncertainty_kg"]) / 1000, alpha=0.2, color="C2")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("mass [t]")
    ax.legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
