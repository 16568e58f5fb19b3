#!/usr/bin/env python3
"""Benchmark harness: each benchmark prints one JSON line
``{"name", "value", "unit", "peer", "peer_value", "ratio"}`` (ratio = peer_value / value for times,
so above 1 means we are faster; each benchmark states its ratio's direction in its name/unit).

Benchmarks live in ``tools/benchmarks/*.py``; each module lists callables in ``BENCHMARKS``, each
taking ``quick: bool`` and returning a list of result dicts. Usage::

    python tools/bench.py [--quick] [NAME_SUBSTRING ...]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
CACHE_DIR = HERE.parent / ".bench-cache"
"""Large generated inputs (not in git)."""


def result(name: str, value: float, unit: str, peer: str | None = None, peer_value: float | None = None,
           ratio: float | None = None, **extra) -> dict:
    """One benchmark line; ``ratio`` defaults to peer_value / value."""
    if ratio is None and peer_value is not None and value:
        ratio = peer_value / value
    return {"name": name, "value": value, "unit": unit, "peer": peer, "peer_value": peer_value,
            "ratio": ratio, **extra}


def discover() -> list:
    benchmarks = []
    for path in sorted((HERE / "benchmarks").glob("*.py")):
        if path.name.startswith("_"):
            continue
        spec = importlib.util.spec_from_file_location(f"haulprofile_bench_{path.stem}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        benchmarks.extend(getattr(module, "BENCHMARKS", []))
    return benchmarks


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="small sizes (seconds, for a smoke test)")
    parser.add_argument("names", nargs="*", help="run only benchmarks whose name contains one of these")
    args = parser.parse_args(argv)
    CACHE_DIR.mkdir(exist_ok=True)
    for bench in discover():
        if args.names and not any(n in bench.__name__ for n in args.names):
            continue
        for line in bench(args.quick):
            print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    sys.exit(main())
