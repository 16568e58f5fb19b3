"""The unit of every column that leaves the program, from the name glossary (``speed_mps`` is in
m/s) or, for a DBC signal, from the DBC; written into Parquet field metadata (``unit``), a CSV's
``<name>.units.json`` sidecar, MF4 channels and the Foxglove copy's JSON schema."""

from __future__ import annotations

import json
from pathlib import Path

SUFFIX_UNITS = {
    "_ns": "ns", "_s": "s", "_h": "h", "_hz": "Hz", "_mps": "m/s", "_mps2": "m/s²", "_kmh": "km/h",
    "_m": "m", "_km": "km", "_deg": "deg", "_rad": "rad", "_radps": "rad/s", "_rpm": "rpm",
    "_pct": "%", "_pa": "Pa", "_c": "°C", "_kg": "kg", "_n": "N", "_nm": "Nm", "_w": "W", "_kw": "kW",
    "_kwh": "kWh", "_lph": "l/h", "_l": "l", "_t": "T", "_m2": "m²",
}
"""Name suffix → unit, the glossary every column name follows (`analysis.signals`)."""
DIMENSIONLESS = {"valid", "current_gear", "brake_switch", "satellites", "fix_quality", "hdop",
                 "gps_hdop", "gps_vdop"}
UNITS_KEY = "units"
"""``DataFrame.attrs`` key of the units that no name tells (DBC signals): column → unit."""
PARQUET_UNIT = b"unit"
SIDECAR_SUFFIX = ".units.json"


def unit_of(column: str, known: dict[str, str] | None = None) -> str:
    """The unit of a column ("" dimensionless or unknown); ``known`` (DBC units) first."""
    if known and column in known:
        return known[column]
    if column in DIMENSIONLESS:
        return ""
    for suffix in sorted(SUFFIX_UNITS, key=len, reverse=True):
        if column.endswith(suffix):
            return SUFFIX_UNITS[suffix]
    return ""


def column_units(frame) -> dict[str, str]:
    """Unit of every column of a table (its ``attrs["units"]`` first)."""
    known = frame.attrs.get(UNITS_KEY, {})
    return {str(c): unit_of(str(c), known) for c in frame.columns}


def sidecar(path: Path) -> Path:
    """The units file beside a CSV table: ``signals.csv`` → ``signals.csv.units.json``."""
    return path.with_name(path.name + SIDECAR_SUFFIX)


def write_sidecar(frame, path: Path) -> Path:
    target = sidecar(path)
    target.write_text(json.dumps(column_units(frame), indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return target


def read_sidecar(path: Path) -> dict[str, str]:
    """Units of a CSV table from its sidecar ({} without one, or one that is not a JSON object of strings)."""
    target = sidecar(Path(path))
    try:
        units = json.loads(target.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(units, dict):
        return {}
    return {str(k): str(v) for k, v in units.items() if isinstance(v, str)}


def parquet_schema(table, units: dict[str, str]):
    """A pyarrow table whose fields carry ``unit`` metadata."""
    import pyarrow as pa

    fields = []
    for field in table.schema:
        metadata = dict(field.metadata or {})
        unit = units.get(field.name)
        if unit is not None:
            metadata[PARQUET_UNIT] = unit.encode()
        fields.append(field.with_metadata(metadata))
    return table.cast(pa.schema(fields, metadata=table.schema.metadata))


def parquet_units(path: Path) -> dict[str, str]:
    """``unit`` of every field of a Parquet file that has one."""
    import pyarrow.parquet as pq

    schema = pq.read_schema(path)
    return {f.name: f.metadata[PARQUET_UNIT].decode() for f in schema if f.metadata and PARQUET_UNIT in f.metadata}
