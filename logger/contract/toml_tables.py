"""Dataclasses from TOML tables, checked key by key: the one checker behind the analysis's vehicle
and scenario files and the logger's configuration.

Unknown keys, missing keys, values of the wrong type and values outside the physically possible
range (the usual sign of a wrong unit) each raise the caller's error class with one line that
names the table and the key. Shared by both programs, so it imports neither.
"""

from __future__ import annotations

import typing
from dataclasses import MISSING, fields
from typing import Callable

Check = Callable[[str, str, object, str], object]
"""``check(where, key, value, annotation) -> value`` for one key of a table."""


def table_kwargs(cls, data, where: str, check: Check, error: type[Exception], allowed: set[str] | None = None,
                 ignore: tuple[str, ...] = (), key_name: Callable[[str], str] = "'{}'".format) -> dict:
    """Keyword arguments of ``cls`` from one table. ``allowed`` limits the fields read from it;
    keys in ``ignore`` may stand in the table but are read by the caller; ``key_name`` spells a
    key in the messages."""
    if not isinstance(data, dict):
        raise error(f"{where}: expected a table, got {data!r}")
    allowed = (allowed if allowed is not None else {f.name for f in fields(cls)}) - set(ignore)
    for key in data:
        if key not in allowed and key not in ignore:
            raise error(f"{where}: unknown key {key_name(key)} (known: {', '.join(sorted(allowed))})")
    kwargs = {}
    for f in fields(cls):
        if f.name not in allowed:
            continue
        if f.name not in data:
            if f.default is MISSING and f.default_factory is MISSING:
                raise error(f"{where}: missing key {key_name(f.name)}")
            continue
        kwargs[f.name] = check(where, f.name, data[f.name], str(f.type))
    return kwargs


def check_text(where: str, key: str, value, error: type[Exception]) -> str:
    if not isinstance(value, str):
        raise error(f"{where}.{key}: expected text, got {value!r}")
    return value


def is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_number(where: str, key: str, value, possible: tuple[float, float], error: type[Exception],
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


def check_typed(name: str, value, annotation, error: type[Exception]):
    """``value`` of the key ``name`` as its annotation asks (bool, int, float, str, a table (dict,
    checked by the caller) or a list of them); an int is accepted for a float."""
    if typing.get_origin(annotation) is list:
        (item_type,) = typing.get_args(annotation)
        if not isinstance(value, list):
            raise error(f"{name} must be a list, got {value!r}")
        return [check_typed(f"{name}[{i}]", v, item_type, error) for i, v in enumerate(value)]
    if annotation is bool:
        if not isinstance(value, bool):
            raise error(f"{name} must be true or false, got {value!r}")
        return value
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise error(f"{name} must be an integer, got {value!r}")
        return value
    if annotation is float:
        if not is_number(value):
            raise error(f"{name} must be a number, got {value!r}")
        return float(value)
    if annotation is str:
        if not isinstance(value, str):
            raise error(f"{name} must be a string, got {value!r}")
        return value
    if annotation is dict:
        if not isinstance(value, dict):
            raise error(f"{name} must be a table, got {value!r}")
        return value
    raise TypeError(annotation)
