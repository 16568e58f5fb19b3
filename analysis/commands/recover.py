"""``analyze recover LOG [-o REPAIRED]``: a repaired, indexed copy of a cut or damaged MCAP log."""

from __future__ import annotations

from pathlib import Path

from .. import checks
from ..ingest.recover import recover


def add_arguments(parser) -> None:
    parser.add_argument("log", type=Path, help="the cut or damaged MCAP log (left untouched)")
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path,
                        help="repaired copy to write (default: LOG with .recovered.mcap)")


def run(args) -> int:
    output = args.out or args.log.with_name(args.log.stem + ".recovered.mcap")
    checks.output_file(output, [args.log], {".mcap"}, what="MCAP log")
    report = recover(args.log, output)
    print(report.warning() or f"{args.log}: intact ({report.messages} messages)")
    print(f"wrote {output}: {report.messages} messages with chunk indexes and summary")
    return 0
