"""``analyze loads SIGNALS --vehicle FILE [--cycle CYCLE] [--mass-kg KG] [--flat-road] [--out DIR]``."""

from __future__ import annotations

from pathlib import Path

from ..errors import UserError
from ..signals import missing_for, read_signals
from ..vehicle import load_vehicle
from .arguments import add_known_road_and_mass, add_out, add_vehicle, check_mass_kg, in_flags

HINTS = {"mass_kg": "--mass-kg", "gradient_pct": "--flat-road"}
"""What gives a column the signals lack when no stage could estimate it."""


def add_arguments(parser) -> None:
    parser.add_argument("signals", type=Path,
                        help="signals table (CSV/Parquet) with time_s and speed_mps; accel_mps2, gradient_pct and "
                             "mass_kg as analyze run writes them, else estimated or given (--mass-kg, --flat-road)")
    add_vehicle(parser)
    parser.add_argument("--cycle", type=Path,
                        help="generated cycle to compare: a table (time_s, speed_mps, accel_mps2, gradient_pct, "
                             "mass_kg) or a VECTO .vdri")
    add_known_road_and_mass(parser)
    add_out(parser, Path("loads-out"))
    parser.add_argument("--load-bins", type=Path, help="TOML file of bin edges replacing the vehicle class's")


def run(args) -> int:
    from ..gradient.stage import GradientOptions
    from ..loads import NEEDED
    from ..loads.bins import read_overrides
    from ..loads.stage import LoadsOptions
    from ..mass.stage import MassOptions
    from ..outputs import OutputOptions
    from ..pipeline import Options, RunContext, run as run_pipeline

    check_mass_kg(args.mass_kg)
    signals = read_signals(args.signals)
    missing = missing_for(signals, NEEDED)
    if args.mass_kg is not None or args.flat_road:
        missing = missing or ["(given)"]
    options = Options(gradient=GradientOptions(keep_existing=True, flat_road=args.flat_road),
                      mass=MassOptions(keep_existing=True, known_mass_kg=args.mass_kg),
                      loads=LoadsOptions(generated_file=args.cycle,
                                         bin_overrides=read_overrides(args.load_bins) if args.load_bins else ()),
                      output=OutputOptions(flat=("loads",)))
    ctx = RunContext(inputs=[], out_dir=args.out, vehicle=load_vehicle(args.vehicle), signals=signals,
                     options=options, say=lambda _msg: None)
    ctx = run_pipeline(ctx, start="kinematics" if missing else "loads", until="loads", leave_out=("cycle",))
    if ctx.results.loads is None:
        lacking = missing_for(ctx.signals, NEEDED)
        hints = [f"{column} ({HINTS[column]})" for column in lacking if column in HINTS]
        why = "; ".join(f"{name}: {in_flags(reason)}" for name, reason in ctx.skipped.items() if name != "loads")
        raise UserError(f"{args.signals}: the measured drive lacks {', '.join(lacking)}"
                        + (f" ({why})" if why else "")
                        + (f"; give {', '.join(hints)}" if hints else "") + ", or run 'analyze run' first")
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
