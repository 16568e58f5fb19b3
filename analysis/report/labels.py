"""Readable names with units for the summary's field names, so a table reads "mean speed [km/h]"
rather than ``speed_mps_mean``; the report shows no raw field name (tests/test_report.py)."""

from __future__ import annotations

import re

_QUANTITY = {"speed_mps": ("speed", "km/h", 3.6), "gradient_pct": ("gradient", "%", 1.0),
             "accel_mps2": ("acceleration", "m/s²", 1.0), "mass_kg": ("mass", "t", 1e-3)}
_STATISTIC = {"mean": "mean", "std": "standard deviation of", "min": "minimum", "max": "maximum"}
_FIXED = {
    "positive_wheel_energy_kwh_per_km": ("positive wheel energy", "kWh/km", 1.0),
    "negative_wheel_energy_kwh_per_km": ("negative wheel energy", "kWh/km", 1.0),
    "speed_torque_residence_distance": ("speed × torque residence: distance of the time shares", "-", 1.0),
    "curvature_psd": ("gradient random walk the smoother chose (how hilly the road is)", "1/m", 1.0),
    "baro_sigma_m": ("barometric height noise", "m", 1.0),
    "imu_sigma_mps2": ("accelerometer noise", "m/s²", 1.0),
    "dem_sigma_m": ("elevation model error", "m", 1.0),
    "dem_correlation_m": ("correlation length of the elevation model error", "m", 1.0),
    "imu_bias_mps2": ("IMU bias (mounting pitch and sensor)", "m/s²", 1.0),
    "imu_bias_std_mps2": ("spread of the IMU bias", "m/s²", 1.0),
    "rolling_resistance_coefficient": ("rolling resistance coefficient c_r", "-", 1.0),
    "drag_area_m2": ("drag area c_d·A", "m²", 1.0),
}
_DAMAGE = re.compile(r"damage_equivalent_torque_range_k(\d+)_nm")
_POWER = re.compile(r"wheel_power_exceeded_(\d+)pct_w")


def label(name: str) -> tuple[str, str, float]:
    """(readable name, unit, factor from the field's SI value to that unit) of a summary field; a
    name it does not know comes back with its underscores as spaces."""
    if name in _FIXED:
        return _FIXED[name]
    if match := _DAMAGE.fullmatch(name):
        return f"damage-equivalent torque range, k = {match.group(1)}", "kNm", 1e-3
    if match := _POWER.fullmatch(name):
        return f"wheel power exceeded {match.group(1)} % of the time", "kW", 1e-3
    quantity, _, statistic = name.rpartition("_")
    if quantity in _QUANTITY and statistic in _STATISTIC:
        what, unit, scale = _QUANTITY[quantity]
        return f"{_STATISTIC[statistic]} {what}", unit, scale
    return name.replace("_", " "), "", 1.0


def labelled(name: str) -> str:
    """"readable name [unit]" of a summary field."""
    text, unit, _ = label(name)
    return f"{text} [{unit}]" if unit else text


def significant(value: float | None, digits: int = 2) -> float | None:
    """``value`` rounded to ``digits`` significant digits (an uncertainty: 624.7 → 620)."""
    if value is None or value != value or value == 0:
        return value
    from math import floor, log10

    return round(value, digits - 1 - floor(log10(abs(value))))
