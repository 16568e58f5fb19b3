"""``analyze export LOG… --to mf4|blf|asc|candump|foxglove -o DIR``: copies of logs in the formats
of asammdf/CANedge, Vector, candump and Foxglove (the inputs are left as they are)."""

from __future__ import annotations

import sys
from pathlib import Path

from .. import checks
from .arguments import add_inputs, add_out, add_rate


def add_arguments(parser) -> None:
    from ..export import FORMATS

    add_inputs(parser, "MCAP logs, directories of them, or other loggers' CAN logs (never modified)")
    parser.add_argument("--to", required=True, choices=list(FORMATS),
                        help="mf4 (CANedge/asammdf bus logging + decoded signals), blf, asc (Vector), "
                             "candump (-L log), foxglove (MCAP with JSON schemas: signals, IMU, map)")
    add_out(parser, what="directory for the exported files (one per log, named after it; none is overwritten)")
    add_rate(parser)
    parser.add_argument("--dbc", type=Path, help="DBC file whose signals are decoded too (mf4, foxglove)")
    parser.add_argument("--private", action="store_true",
                        help="no wall-clock time, positions, NMEA or J1939 position/date frames in the exports")
    parser.add_argument("--quiet", action="store_true", help="print only errors")


def run(args) -> int:
    from ..export import export_logs

    checks.rate_hz(args.rate_hz)
    say = (lambda _msg: None) if args.quiet else (lambda msg: print(msg, file=sys.stderr))
    export_logs(args.inputs, args.to, args.out, private=args.private, rate_hz=args.rate_hz, dbc=args.dbc, say=say)
    return 0
