"""Dataclasses from TOML tables, checked key by key: the vehicle file and the scenario files.

Unknown keys, missing keys, values of the wrong type and values outside the physically possible
range (the usual sign of a wrong unit) each raise the caller's error class with one line that
names the table and the key.
"""

from __future__ import annotations

from dataclasses import MISSING, fields
from typing import Callable

from .errors import UserError

Check = Callable[[str, str, object, str], object]
"""``check(where, key, value, annotation) -> value`` for one key of a table."""


def table_kwargs(cls, data, where: str, check: Check, error: type[UserError], allowed: set[str] | None = None,
                 ignore: tuple[str, ...] = ()) -> dict:
    """Keyword arguments of ``cls`` from one table. ``allowed`` limits the fields read from it;
    keys in ``ignore`` may stand in the table but are read by the caller."""
    if not isinstance(data, dict):
        raise error(f"{where}: expected a table, got {data!r}")
    allowed = (allowed if allowed is not None else {f.name for f in fields(cls)}) - set(ignore)
    for key in data:
        if key not in allowed and key not in ignore:
            raise error(f"{where}: unknown key '{key}' (known: {', '.join(sorted(allowed))})")
    kwargs = {}
    for f in fields(cls):
        if f.name not in allowed:
            continue
        if f.name not in data:
            if f.default is MISSING and f.default_factory is MISSING:
                raise error(f"{where}: missing key '{f.name}'")
            continue
        kwargs[f.name] = check(where, f.name, data[f.name], str(f.type))
    return kwargs


def check_text(where: str, key: str, value, error: type[UserError]) -> str:
    if not isinstance(value, str):
        raise error(f"{where}.{key}: expected text, got {value!r}")
    return value


def is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_number(where: str, key: str, value, possible: tuple[float, float], error: type[UserError],
                 whole: bool = False) -> float | int:
    """A number within ``possible`` = (low, high); ``whole`` asks for an integer."""
    if whole:
        if isinstance(value, bool) or not isinstance(value, int):
            raise error(f"{where}.{key}: expected a whole number, got {value!r}")
    elif not is_number(value):
        raise error(f"{where}.{key}: expected a number in the unit its name gives, got {value!r}")
    low, high = possible
    if not low <= value <= high:
        raise error(f"{where}.{key} = {value} is outside the possible range [{low:g}, {high:g}] (wrong unit?)")
    return value if whole else float(value)
