"""Plausible ranges of the physical columns of a signals table: a value outside its range is a
sensor's glitch or a unit mistake, never taken silently.

A column whose typical (median) value lies in the range of a known wrong unit (pressure in hPa or
kPa, temperature in kelvin) is refused with one line naming the unit; single samples outside the
range become NaN (missing) and one note per column says how many, so an estimate never rests on
a pressure of 1e308 Pa, a latitude of 200° or a torque of 1e12 Nm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .errors import UserError


@dataclass(frozen=True)
class Range:
    low: float
    high: float
    unit: str
    why: str
    wrong_units: tuple[tuple[str, float, float], ...] = ()
    """(unit, low, high) of a median that says the column is in that unit."""


RANGES = {
    "pressure_pa": Range(20_000.0, 120_000.0, "Pa", "air pressure from 12 km altitude to a deep mine",
                         (("hPa", 200.0, 1200.0), ("kPa", 20.0, 120.0), ("bar", 0.2, 1.2))),
    "air_temperature_c": Range(-60.0, 70.0, "degC", "air on a road",
                               (("K (kelvin)", 210.0, 345.0), ("degF", 71.0, 160.0))),
    "latitude_deg": Range(-90.0, 90.0, "deg", "a latitude"),
    "longitude_deg": Range(-180.0, 180.0, "deg", "a longitude"),
    "gps_altitude_m": Range(-500.0, 9000.0, "m", "a road's height"),
    "gps_h_acc_m": Range(0.0, 10_000.0, "m", "a GNSS accuracy"),
    "gps_v_acc_m": Range(0.0, 10_000.0, "m", "a GNSS accuracy"),
    "gps_hdop": Range(0.0, 100.0, "", "a dilution of precision"),
    "gps_vdop": Range(0.0, 100.0, "", "a dilution of precision"),
    "engine_speed_rpm": Range(0.0, 6000.0, "rpm", "a truck engine's speed"),
    "engine_torque_nm": Range(-5000.0, 10_000.0, "Nm", "a truck engine's torque (drag to peak)"),
    "accel_x_mps2": Range(-50.0, 50.0, "m/s^2", "a vehicle's acceleration (5 g)"),
    "reported_mass_kg": Range(500.0, 200_000.0, "kg", "a road vehicle's mass", (("t", 0.5, 200.0),)),
}


def check_ranges(frame: pd.DataFrame, source: str, say=None) -> pd.DataFrame:
    """``frame`` with samples outside `RANGES` set to NaN (one note per column through ``say``);
    `UserError` for a column whose median says it is in another unit."""
    changed = None
    for name, allowed in RANGES.items():
        if name not in frame.columns:
            continue
        values = pd.to_numeric(frame[name], errors="coerce").to_numpy(dtype=float, copy=True)
        finite = values[np.isfinite(values)]
        if not len(finite):
            continue
        median = float(np.median(finite))
        if not allowed.low <= median <= allowed.high:
            for unit, low, high in allowed.wrong_units:
                if low <= median <= high:
                    raise UserError(f"{source}: {name} has a median of {median:g}, which is {unit}, not "
                                    f"{allowed.unit}; convert it to {allowed.unit}")
        outside = np.isfinite(values) & ((values < allowed.low) | (values > allowed.high)) | np.isinf(values)
        if outside.any():
            if changed is None:
                changed = frame.copy()
            values[outside] = np.nan
            changed[name] = values
            if say is not None:
                say(f"{source}: {name}: {int(outside.sum())} of {len(values)} value(s) outside "
                    f"{allowed.low:g} to {allowed.high:g} {allowed.unit} ({allowed.why}) left out as missing, "
                    f"e.g. {values_example(frame[name], outside)}")
    return frame if changed is None else changed


def values_example(column: pd.Series, outside: np.ndarray) -> str:
    return f"{float(pd.to_numeric(column, errors='coerce').to_numpy(dtype=float)[outside][0]):g}"


def known_mass_kg(value: float, what: str) -> float:
    """A weighed mass [kg] (``--known-mass``): within a road vehicle's range, else one `UserError`
    (0.001 kg once became a torque gain of 1.6e7)."""
    allowed = RANGES["reported_mass_kg"]
    if not allowed.low <= value <= allowed.high:
        raise UserError(f"{what}: {value:g} kg is not {allowed.why} ({allowed.low:g} to {allowed.high:g} kg); "
                        "give the weighed mass in kg")
    return value
