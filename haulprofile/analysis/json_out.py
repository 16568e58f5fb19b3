"""JSON that strict parsers read: what ``summary.json``, ``fleet-summary.json`` and ``--json`` print.

Python's ``json`` writes ``NaN`` and ``Infinity`` by default, which JavaScript, jq and most other
languages refuse. Here a number that is not finite becomes ``null``, NumPy values become plain
numbers and lists, paths become strings, and the top level carries ``schema_version`` (every key
is documented in ``docs/summary-json.md``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

SCHEMA_VERSION = 1
"""Raised when a key changes meaning or is removed; new keys keep the version."""


def plain(value):
    """``value`` with NumPy scalars/arrays, paths and non-finite numbers made JSON-safe (NaN/±inf → None)."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist"):  # NumPy scalars and arrays
        return plain(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return str(value)


def dumps(summary: dict, indent: int | None = None) -> str:
    """A summary as strict JSON, ``schema_version`` first."""
    return json.dumps({"schema_version": SCHEMA_VERSION, **plain(summary)}, indent=indent, allow_nan=False)
