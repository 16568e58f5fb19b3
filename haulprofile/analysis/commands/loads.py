"""``analyze loads SIGNALS --vehicle FILE [--cycle CYCLE_CSV] [--out DIR]``."""

from __future__ import annotations

from pathlib import Path

from ..errors import UserError
from ..signals import missing_for, read_signals
from ..vehicle import load_vehicle
from .arguments import add_out, add_vehicle


def add_arguments(parser) -> None:
    parser.add_argument("signals", type=Path,
                        help="signals table (CSV/Parquet) with time_s, speed_mps, accel_mps2, gradient_pct, mass_kg "
                             "(as analyze run writes it)")
    add_vehicle(parser)
    parser.add_argument("--cycle", type=Path,
                        help="generated cycle CSV (time_s, speed_mps, accel_mps2, gradient_pct, mass_kg) to compare")
    add_out(parser, Path("loads-out"))


def run(args) -> int:
    from ..loads import NEEDED
    from ..loads.stage import LoadsOptions
    from ..outputs import OutputOptions
    from ..pipeline import Options, RunContext, run as run_pipeline

    signals = read_signals(args.signals)
    missing = missing_for(signals, NEEDED)
    if missing:
        raise UserError(f"{args.signals}: the measured drive lacks {', '.join(missing)}; run 'analyze run' first "
                        f"to estimate them")
    ctx = RunContext(inputs=[], out_dir=args.out, vehicle=load_vehicle(args.vehicle), signals=signals,
                     options=Options(loads=LoadsOptions(generated_file=args.cycle),
                                     output=OutputOptions(flat=("loads",))), say=lambda _msg: None)
    ctx = run_pipeline(ctx, start="loads", until="loads")
    result = ctx.summary["loads"]
    for name, s in result.items():
        if name == "comparison":
            continue
        dets = ", ".join(f"k={k}: {v:.0f}" for k, v in s["damage_equivalent_torque_range_nm"].items())
        print(f"{name}: {s['duration_s']:.0f} s, {s['distance_km']:.2f} km, {s['rainflow_cycles']:.0f} rainflow cycles; "
              f"damage-equivalent torque range [Nm] {dets}")
    comparison = ctx.results.loads.comparison
    if comparison is not None:
        print(comparison.to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    print(f"wrote {args.out}")
    return 0
