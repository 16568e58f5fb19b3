"""The one JSON helper of the analysis: NumPy scalars and arrays, paths and dataclasses as JSON, and
strict JSON for the files and ``--json`` output other tools read.

Python's ``json`` writes ``NaN`` and ``Infinity`` by default, which JavaScript, jq and most other
languages refuse. `dumps` writes a number that is not finite as ``null`` and puts ``schema_version``
at the top level (every key of ``summary.json`` is documented in ``docs/summary-json.md``).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

SCHEMA_VERSION = 1
"""Raised when a key changes meaning or is removed; new keys keep the version."""


def jsonable(value):
    """``json.dumps`` default for NumPy scalars/arrays, paths and dataclasses."""
    if hasattr(value, "item") and getattr(value, "ndim", 0) == 0:
        return value.item()
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def plain(value):
    """``value`` as plain JSON types, with non-finite numbers (NaN, ±inf) as None."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    try:
        return plain(jsonable(value))
    except TypeError:
        return str(value)


def dumps(value, indent: int | None = None, versioned: bool = True) -> str:
    """``value`` as strict JSON; a ``versioned`` dict gets ``schema_version`` first."""
    body = plain(value)
    if versioned and isinstance(body, dict):
        body = {"schema_version": SCHEMA_VERSION, **body}
    return json.dumps(body, indent=indent, allow_nan=False)
