"""Typed stage options from plain keyword tables (the Python API's ``cycle={"seed": 1}``).

A stage's options are a dataclass; a table's keys are its fields, or the fields of a dataclass it
holds (``mass={"forgetting_factor": 0.99}`` reaches `SegmentSettings` inside `MassOptions`), so a
caller never needs to know how a stage groups its settings. An unknown key is a one-line error.
"""

from __future__ import annotations

import typing
from dataclasses import fields, is_dataclass, replace

from .errors import UserError


class OptionsError(UserError):
    pass


def _nested(cls) -> dict[str, type]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in fields(cls) if is_dataclass(hints.get(f.name))}


def options_of(cls, table, where: str):
    """``table`` (None, a dict or already a ``cls``) as a ``cls`` instance."""
    if isinstance(table, cls):
        return table
    if table is None:
        return cls()
    if not isinstance(table, dict):
        raise OptionsError(f"{where} options: expected a table of keywords or {cls.__name__}, got {table!r}")
    own = {f.name for f in fields(cls)}
    nested = _nested(cls)
    direct, routed = {}, {name: {} for name in nested}
    for key, value in table.items():
        if key in own:
            direct[key] = options_of(nested[key], value, f"{where}.{key}") if key in nested else value
            continue
        holder = next((name for name, sub in nested.items() if key in {f.name for f in fields(sub)}), None)
        if holder is None:
            known = sorted(own | {f.name for sub in nested.values() for f in fields(sub)})
            raise OptionsError(f"{where} options: unknown key '{key}' (known: {', '.join(known)})")
        routed[holder][key] = value
    options = cls(**direct)
    for name, values in routed.items():
        if values:
            options = replace(options, **{name: replace(getattr(options, name), **values)})
    return options
