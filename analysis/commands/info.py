"""``analyze info LOG…``: topics, duration, rates, gaps, recovered bytes and decoded signal coverage."""

from __future__ import annotations

import sys
from pathlib import Path

from .. import jsonable
from ..ingest import ingest_logs
from .arguments import add_inputs


def add_arguments(parser) -> None:
    add_inputs(parser, "MCAP logs, directories of them, or foreign CAN logs")
    parser.add_argument("--dbc", type=Path, help="DBC file for further signals")
    parser.add_argument("--json", action="store_true", help="print the whole ingest summary as JSON")


def run(args) -> int:
    def say(msg: str) -> None:
        if args.json or not msg.startswith("warning: "):  # the summary below lists the warnings once
            print(msg, file=sys.stderr)

    _, summary = ingest_logs(args.inputs, dbc=args.dbc, progress=sys.stderr.isatty(), say=say)
    if args.json:
        print(jsonable.dumps(summary, indent=2))
        return 0
    print("\n".join(describe(summary)))
    return 0


def describe(summary: dict) -> list[str]:
    """Human-readable lines of an ingest summary."""
    lines = []
    duration = summary.get("duration_s", 0.0)
    for f in summary.get("files", []):
        state = "complete" if f["complete"] else "CUT (no footer)"
        lines.append(f"{f['path']}: {f['bytes']} bytes, {state}, recovered {f['recovered_bytes']} bytes, "
                     f"{f['chunks']} chunks ({f['bad_chunks']} damaged), {f['messages']} messages")
    lines.append(f"duration {duration:.1f} s, {summary.get('rows', 0)} rows at {summary.get('rate_hz', 0):g} Hz, "
                 f"{summary.get('valid_fraction', 0):.1%} valid, {summary.get('gaps', 0)} gaps "
                 f"({summary.get('gap_s', 0):.1f} s)")
    if summary.get("source") == "signals table":
        lines.append("signal coverage (share of valid rows with a value):")
        lines += [f"  {column:<28} {share:7.1%}" for column, share in summary.get("coverage", {}).items()]
        return lines
    lines.append("topics (messages, rate):")
    for topic, count in sorted(summary.get("topics", {}).items()):
        lines.append(f"  {topic:<28} {count:>10}  {count / duration if duration else 0:8.2f} /s")
    lines.append(f"CAN frames {summary.get('can_frames', 0)} ({summary.get('can_frames', 0) / duration if duration else 0:.0f}/s), "
                 f"IMU samples {summary.get('imu_samples', 0)}")
    tp = summary.get("transport_protocol", {})
    lines.append(f"J1939 transport protocol: {tp.get('bam', 0)} BAM, {tp.get('rts_cts', 0)} RTS/CTS, "
                 f"{tp.get('incomplete', 0)} incomplete, {tp.get('aborted', 0)} aborted")
    obd = summary.get("obd", {})
    if obd.get("requests") or obd.get("responses"):
        lines.append(f"OBD-II: {obd['requests']} requests, {obd['matched']} matched responses, "
                     f"{obd['unrequested']} unrequested")
    lines.append("signal coverage (share of valid rows with a value) and source:")
    sources = summary.get("sources", {})
    for column, share in summary.get("coverage", {}).items():
        source = sources.get(column, {}).get("key", "")
        lines.append(f"  {column:<28} {share:7.1%}  {source if isinstance(source, str) else ', '.join(source)}")
    for warning in summary.get("warnings", []):
        lines.append(f"warning: {warning}")
    return lines
