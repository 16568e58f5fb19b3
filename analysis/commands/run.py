"""``analyze run INPUT… --vehicle FILE [--dem DIR] --out DIR``."""

from __future__ import annotations

from pathlib import Path

from ..pipeline import RunContext, run as run_pipeline
from ..vehicle import load_vehicle


def add_arguments(parser) -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help="MCAP logs, directories of logs, or signals tables")
    parser.add_argument("--vehicle", required=True, help="vehicle file (TOML) or a shipped example name")
    parser.add_argument("--dem", type=Path, help="directory of SRTM .hgt tiles (or GeoTIFFs)")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--quiet", action="store_true", help="print only errors")


def run(args) -> int:
    ctx = RunContext(inputs=list(args.inputs), out_dir=args.out, vehicle=load_vehicle(args.vehicle),
                     dem_dir=args.dem, say=(lambda _msg: None) if args.quiet else print)
    run_pipeline(ctx)
    ctx.say(f"wrote {args.out / 'signals.parquet'} and {args.out / 'summary.json'}")
    return 0
