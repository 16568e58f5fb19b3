"""The one JSON helper of the analysis: NumPy scalars and arrays, paths and dataclasses as JSON."""

from __future__ import annotations

import dataclasses
from pathlib import Path


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
