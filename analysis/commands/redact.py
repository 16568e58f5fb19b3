"""``analyze redact LOG… --zones FILE --out DIR``: copies of logs without positions, NMEA and GPS
times recorded inside privacy zones (the inputs are left as they are)."""

from __future__ import annotations

from pathlib import Path

from ..encrypted import read_bytes
from ..errors import UserError
from ..redact import load_zones, redact_files


def add_arguments(parser) -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help="MCAP logs or directories of them (never modified)")
    parser.add_argument("--zones", type=Path, required=True,
                        help="TOML with [[zones]] (circles: lat, lon, radius_m; or polygon = [[lat, lon], ...]) "
                             "or a logger configuration with [[privacy.zones]]")
    parser.add_argument("--out", type=Path, required=True, help="directory for the redacted copies (same names)")


def inputs_of(paths: list[Path]) -> list[Path]:
    files = []
    for path in paths:
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.is_file() and p.name.endswith((".mcap", ".mcap.age")))
            if not found:
                raise UserError(f"{path}: directory holds no .mcap logs")
            files.extend(found)
        elif path.is_file():
            files.append(path)
        else:
            raise UserError(f"input {path} not found")
    return files


def run(args) -> int:
    zones = load_zones(args.zones)
    for report in redact_files(inputs_of(args.inputs), zones, args.out, read=read_bytes):
        print(report.line())
    return 0
