"""``analyze signals LOG… -o signals.parquet``: decode and align logs into a signals table."""

from __future__ import annotations

import sys
from pathlib import Path

from .. import checks
from .. import signals as signals_table
from .arguments import add_inputs, add_out, add_rate, printer


def add_arguments(parser) -> None:
    add_inputs(parser, "MCAP logs, directories of them, or .log/.asc/.blf/.mf4 CAN logs of other loggers")
    add_out(parser, what="signals table to write (.parquet or .csv)")
    add_rate(parser)
    parser.add_argument("--dbc", type=Path, help="DBC file whose signals are decoded into further columns")
    parser.add_argument("--quiet", action="store_true", help="print only errors")


def run(args) -> int:
    from ..ingest.stage import IngestOptions
    from ..outputs import OutputOptions
    from ..pipeline import Options, RunContext, run as run_pipeline

    checks.output_file(args.out, args.inputs, signals_table.SIGNALS_SUFFIXES, what="signals table")
    checks.rate_hz(args.rate_hz)
    say = printer(args.quiet, sys.stderr)
    options = IngestOptions(rate_hz=args.rate_hz, dbc=args.dbc, progress=not args.quiet and sys.stderr.isatty())
    ctx = RunContext(inputs=list(args.inputs), out_dir=args.out.parent,
                     options=Options(ingest=options, output=OutputOptions(signals_file=args.out.name)), say=say)
    ctx = run_pipeline(ctx, until="ingest")
    frame, summary = ctx.signals, ctx.summary.get("ingest", {})
    say(f"wrote {args.out}: {len(frame)} rows at {args.rate_hz:g} Hz, {summary.get('valid_fraction', 1.0):.0%} valid, "
        f"columns {', '.join(c for c in frame.columns if c not in ('time_s', 'valid'))}")
    return 0
