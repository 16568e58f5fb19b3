"""``analyze loads SIGNALS --vehicle FILE [--cycle CYCLE_CSV] [--out DIR]``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from .. import checks
from ..errors import UserError
from ..signals import missing_for, read_signals
from ..vehicle import load_vehicle


def add_arguments(parser) -> None:
    parser.add_argument("signals", type=Path,
                        help="signals table (CSV/Parquet) with time_s, speed_mps, accel_mps2, gradient_pct, mass_kg "
                             "(as analyze run writes it)")
    parser.add_argument("--vehicle", required=True, help="vehicle file (TOML) or a shipped example name")
    parser.add_argument("--cycle", type=Path,
                        help="generated cycle CSV (time_s, speed_mps, accel_mps2, gradient_pct, mass_kg) to compare")
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path, default=Path("loads-out"),
                        help="output directory")


def _drive(path: Path, what: str) -> pd.DataFrame:
    from ..loads import NEEDED

    frame = read_signals(path)
    missing = missing_for(frame, NEEDED)
    if missing:
        raise UserError(f"{path}: the {what} lacks {', '.join(missing)}; run 'analyze run' first to estimate them")
    return frame


def run(args) -> int:
    from ..loads import collectives_of, write_all

    checks.output_dir(args.out, [args.signals] + ([args.cycle] if args.cycle else []))
    vehicle = load_vehicle(args.vehicle)
    drives = {"measured": _drive(args.signals, "measured drive")}
    if args.cycle is not None:
        drives["generated"] = _drive(args.cycle, "generated cycle")
    result, comparison = write_all(collectives_of(drives, vehicle), args.out)
    for name, s in result.items():
        if name == "comparison":
            continue
        dets = ", ".join(f"k={k}: {v:.0f}" for k, v in s["damage_equivalent_torque_range_nm"].items())
        print(f"{name}: {s['duration_s']:.0f} s, {s['distance_km']:.2f} km, {s['rainflow_cycles']:.0f} rainflow cycles; "
              f"damage-equivalent torque range [Nm] {dets}")
    if comparison is not None:
        print(comparison.to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    print(f"wrote {args.out}")
    return 0
