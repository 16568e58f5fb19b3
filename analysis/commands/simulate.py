"""``analyze simulate CYCLE --vehicle FILE [--payload-kg M] [--aux-power-w P] [--out DIR]``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from .. import checks
from ..errors import UserError
from ..vehicle import load_vehicle
from .arguments import add_out, add_vehicle


def add_arguments(parser) -> None:
    parser.add_argument("cycle", type=Path,
                        help="a VECTO .vdri, a time-based CSV/Parquet (time_s, speed_mps[, gradient_pct, "
                             "mass_kg]) or a signals table")
    add_vehicle(parser)
    parser.add_argument("--payload-kg", type=float, help="payload [kg] (default: half the vehicle's max payload)")
    parser.add_argument("--aux-power-w", help="auxiliary power [W]: a number, or a CSV with time_s, power_w "
                                              "(default: the vehicle file's)")
    parser.add_argument("--epto-power-w", default="0", help="ePTO power [W]: a number or a CSV with time_s, power_w")
    parser.add_argument("--obc-power-w", default="0",
                        help="on-board charger power into the battery [W]: a number or a CSV with time_s, power_w")
    parser.add_argument("--time-step-s", type=float, default=0.1, help="integration step [s] (default 0.1)")
    add_out(parser, Path("simulation-out"))


def power_input(text: str | None, name: str):
    """A constant [W] or a (time_s, power_w) CSV as the simulator takes it."""
    if text is None:
        return None
    try:
        return checks.non_negative(float(text), name, "W")
    except ValueError:
        pass
    path = Path(text)
    if not path.is_file():
        raise UserError(f"{name}: give a number in W or a CSV file with time_s, power_w ({text} not found)")
    try:
        table = pd.read_csv(path)
    except (ValueError, UnicodeDecodeError) as exc:  # pandas' ParserError and EmptyDataError are ValueErrors
        raise UserError(f"{name} {path}: not a readable CSV table ({type(exc).__name__})") from None
    columns = {"time_s", "power_w"}
    if not columns <= set(table.columns) or not all(pd.api.types.is_numeric_dtype(table[c]) for c in columns):
        raise UserError(f"{name} {path}: needs numeric columns time_s and power_w, "
                        f"has {', '.join(map(str, table.columns))}")
    return table


def run(args) -> int:
    from ..outputs import OutputOptions
    from ..pipeline import Options, RunContext, run as run_pipeline
    from ..simulate import DriverSettings
    from ..simulate.stage import SimulateOptions

    if not 0.01 <= args.time_step_s <= 1.0:
        raise UserError(f"--time-step-s {args.time_step_s} is outside 0.01..1 s")
    if args.payload_kg is not None:
        checks.non_negative(args.payload_kg, "--payload-kg", "kg")
    options = SimulateOptions(payload_kg=args.payload_kg, aux_power_w=power_input(args.aux_power_w, "--aux-power-w"),
                              epto_power_w=power_input(args.epto_power_w, "--epto-power-w"),
                              obc_power_w=power_input(args.obc_power_w, "--obc-power-w"),
                              driver=DriverSettings(time_step_s=args.time_step_s), cycle_file=args.cycle)
    ctx = RunContext(inputs=[], out_dir=args.out, vehicle=load_vehicle(args.vehicle),
                     options=Options(simulation=options, output=OutputOptions(flat=("simulation",))),
                     say=lambda _msg: None)
    ctx = run_pipeline(ctx, start="simulation", until="simulation")
    s = ctx.results.simulation.numbers
    print(f"{s['cycle']}: {s['distance_km']:.2f} km in {s['duration_s']:.0f} s, "
          f"battery {s['battery_kwh_per_km']:.3f} kWh/km, wheel (positive) {s['wheel_positive_kwh_per_km']:.3f} kWh/km, "
          f"SOC {s['initial_soc']:.3f} -> {s['final_soc']:.3f}, "
          f"{s['missed_target_intervals']} interval(s) below target ({s['missed_target_s']:.1f} s)")
    print(f"wrote {args.out}")
    return 0
