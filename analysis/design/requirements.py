"""What the application needs, at the wheel and, per ratio, at the machine shaft.

Pure functions over drives (tables with ``time_s`` [s], ``speed_mps`` [m/s], ``accel_mps2``
[m/s^2], ``gradient_pct`` [%], ``mass_kg`` [kg]): the measured drive and each selected cycle as
driven. Forces come from the one vehicle model (`analysis.road_load`, via
`analysis.loads.collectives.wheel_loads`), rainflow damage from the loads stage's functions. Each
requirement is evaluated on every drive at the mass estimate and ``k`` standard deviations either
side, and given as (nominal, low, high): nominal is the first drive at the estimate.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from .. import road_load
from ..loads.collectives import damage_equivalent_range, rainflow_cycles, wheel_loads
from .options import DesignOptions

KMH = 3.6
DURATION_SHARES = (0.01, 0.05, 0.5)
"""Shares of moving time for the duration curve: the wheel torque exceeded that long."""
DAMAGE_EXPONENT = 5
"""Woehler slope of the damage-equivalent torque in the requirement table (the loads stage's k=5)."""


def moving_rms(values, time_s, window_s: float) -> float:
    """Largest RMS of ``values`` over any window of ``window_s`` [s] (time-weighted, the whole drive if shorter)."""
    t = np.asarray(time_s, float)
    x = np.asarray(values, float)
    dt = np.diff(t, append=t[-1])
    energy = np.concatenate([[0.0], np.cumsum(x * x * dt)])
    ends = np.searchsorted(t, t + window_s, side="left")
    span = np.minimum(window_s, t[-1] - t[0]) if t[-1] > t[0] else 1.0
    return float(np.sqrt(np.max(energy[ends] - energy[:-1]) / span)) if len(t) else 0.0


def moving_mean(values, time_s, window_s: float) -> float:
    """Largest mean of ``values`` over any window of ``window_s`` [s]."""
    t = np.asarray(time_s, float)
    x = np.asarray(values, float)
    dt = np.diff(t, append=t[-1])
    total = np.concatenate([[0.0], np.cumsum(x * dt)])
    ends = np.searchsorted(t, t + window_s, side="left")
    span = np.minimum(window_s, t[-1] - t[0]) if t[-1] > t[0] else 1.0
    return float(np.max(total[ends] - total[:-1]) / span) if len(t) else 0.0


def grade_force_n(mass_kg, gradient_pct, speed_mps, vehicle, accel_mps2: float = 0.0) -> float:
    """Wheel force [N] to hold ``speed_mps`` (accelerating at ``accel_mps2``) on a grade: equation (1)."""
    return float(road_load.wheel_force_n(speed_mps, accel_mps2, gradient_pct, mass_kg, vehicle))


def acceleration_time_s(frame: pd.DataFrame, target_mps: float) -> float | None:
    """Fastest time [s] from standstill (< 0.5 m/s) to ``target_mps`` without stopping again, as driven."""
    t, v = frame["time_s"].to_numpy(float), frame["speed_mps"].to_numpy(float)
    best, start = None, None
    for i in range(len(v)):
        if v[i] < 0.5:
            start = t[i]
        elif start is not None and v[i] >= target_mps:
            best = t[i] - start if best is None else min(best, t[i] - start)
            start = None
    return best


def mass_offsets(sigma_kg: float, sigmas: float) -> dict[str, float]:
    """Mass offsets [kg] of the cases: the estimate and ``sigmas`` standard deviations either side."""
    return {"low": -sigmas * sigma_kg, "estimate": 0.0, "high": sigmas * sigma_kg}


def gross_mass_kg(vehicle, heaviest_kg: float) -> float:
    """The vehicle's gross mass [kg] (curb plus maximum payload), or the heaviest case if heavier."""
    return max(vehicle.curb_mass_kg + (vehicle.max_payload_kg or 0.0), heaviest_kg)


def wheel_requirements(drive: pd.DataFrame, vehicle, options: DesignOptions, rotating_mass_kg: float = 0.0) -> dict:
    """One drive's requirements at the wheel [N, Nm, W, m/s, %, s, kWh/km]."""
    loads = wheel_loads(drive["time_s"], drive["speed_mps"], drive["accel_mps2"], drive["gradient_pct"],
                        drive["mass_kg"], vehicle, rotating_mass_kg)
    t, torque, power = loads["time_s"].to_numpy(), loads["wheel_torque_nm"].to_numpy(), loads["wheel_power_w"].to_numpy()
    moving = loads["speed_mps"].to_numpy() > 0.5
    durations = loads["duration_s"].to_numpy()
    distance_km = float(np.sum(loads["speed_mps"].to_numpy() * durations)) / 1000.0
    out = {
        "top_speed_driven_mps": float(drive["speed_mps"].max()),
        "max_gradient_pct": float(drive["gradient_pct"][drive["speed_mps"] > 0.5].max()) if moving.any() else 0.0,
        "peak_wheel_torque_nm": float(torque.max()),
        "peak_wheel_power_w": float(power.max()),
        "peak_regen_wheel_power_w": float(-min(power.min(), 0.0)),
        "positive_wheel_kwh_per_km": float(np.sum(np.clip(power, 0, None) * durations)) / 3.6e6 / distance_km
        if distance_km > 0 else math.nan,
        "distance_km": distance_km,
        "duration_s": float(durations.sum()),
    }
    for w in options.thermal_windows_s:
        out[f"rms_wheel_torque_{w:g}s_nm"] = moving_rms(torque, t, w)
        out[f"mean_wheel_power_{w:g}s_w"] = moving_mean(np.abs(power), t, w)
    order = np.sort(torque[moving])[::-1]
    for share in DURATION_SHARES:
        out[f"wheel_torque_exceeded_{share:g}_nm"] = float(order[int(share * (len(order) - 1))]) if len(order) else 0.0
    det = damage_equivalent_range(rainflow_cycles(torque), durations.sum())
    out[f"damage_equivalent_wheel_torque_range_k{DAMAGE_EXPONENT}_nm"] = float(det[DAMAGE_EXPONENT])
    for kmh in (50, 80):
        seconds = acceleration_time_s(drive, kmh / KMH)
        out[f"accel_0_{kmh}_kmh_s"] = math.nan if seconds is None else seconds
    return out


def static_requirements(vehicle, options: DesignOptions, heaviest_kg: float, route_grade_pct: float,
                        route_grade_speed_mps: float) -> dict:
    """Gradeability, startability and top speed at the gross mass [N at the wheel]."""
    gross = gross_mass_kg(vehicle, heaviest_kg)
    return {
        "gross_mass_kg": gross,
        "design_grade_force_n": grade_force_n(gross, options.design_grade_pct, options.design_grade_speed_mps, vehicle),
        "route_grade_force_n": grade_force_n(gross, route_grade_pct, route_grade_speed_mps, vehicle),
        "startability_force_n": grade_force_n(gross, options.startability_grade_pct, 0.0, vehicle,
                                              options.start_acceleration_mps2),
        "top_speed_force_n": grade_force_n(gross, 0.0, options.legal_top_speed_mps, vehicle),
    }


def shaft_requirements(wheel: dict, ratio: float, efficiency: float, wheel_radius_m: float) -> dict:
    """A drive's wheel requirements at the machine shaft for one total ratio [-] and driveline
    efficiency [-]: T = T_wheel / (i eta) when driving, omega = v i / r."""
    out = {"ratio": ratio,
           "peak_machine_torque_nm": wheel["peak_wheel_torque_nm"] / (ratio * efficiency),
           "peak_machine_power_w": wheel["peak_wheel_power_w"] / efficiency,
           "machine_speed_at_top_speed_rpm": wheel["top_speed_driven_mps"] / wheel_radius_m * ratio * 60.0 / (2 * np.pi)}
    for key, value in wheel.items():
        if key.startswith("rms_wheel_torque_"):
            out[key.replace("wheel", "machine")] = value / (ratio * efficiency)
    return out


def requirement_ranges(drives: dict[str, pd.DataFrame], vehicle, options: DesignOptions, sigma_kg: float,
                       rotating_mass_kg: float = 0.0) -> tuple[dict, dict]:
    """Every wheel requirement over drives x mass cases (each drive's ``mass_kg`` shifted by the
    case's offset) as {key: {"value", "low", "high"}}, and the tables {drive: {case: requirements}}."""
    cases = mass_offsets(sigma_kg, options.mass_sigmas)
    table = {name: {case: wheel_requirements(d.assign(mass_kg=d["mass_kg"].to_numpy(float) + offset), vehicle,
                                             options, rotating_mass_kg)
                    for case, offset in cases.items()} for name, d in drives.items()}
    first = next(iter(table))
    ranges = {}
    for key in table[first]["estimate"]:
        values = np.array([table[n][c][key] for n in table for c in cases], float)
        finite = values[np.isfinite(values)]
        ranges[key] = {"value": table[first]["estimate"][key],
                       "low": float(finite.min()) if len(finite) else math.nan,
                       "high": float(finite.max()) if len(finite) else math.nan}
    return ranges, table
