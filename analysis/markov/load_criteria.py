"""Load criteria: is a cycle representative of the measured drive for the powertrain?

The paper's fifteen criteria are kinematic; a cycle that sizes a drive must also carry its wheel
loads. Against the measured drive (its loads from `analysis.loads`, the one vehicle model
`analysis.road_load`, averaged to 1 s windows as the loads stage compares drives) a cycle is
judged on

* positive and negative wheel energy per km,
* damage-equivalent wheel torque ranges for Wöhler exponents k = 3 … 8 (rainflow, ASTM E1049),
* wheel power exceeded 5, 50 and 95 % of the time,
* the speed × torque residence time (total variation distance of the time shares, measured bins;
  scored, not gated: see `GATED`).

Deviation per criterion **[choice]**: relative to the measured value, except where that can be
near zero: negative energy per km is relative to at least a tenth of the positive, a wheel power
level relative to at least a tenth of the measured 5 %…95 % span; the residence distance is
itself the deviation (0 identical, 1 disjoint). Allowances `LOAD_ALLOWANCE`: positive energy
5 %, the others 10 %, residence distance 0.25.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .. import road_load
from ..loads import loads_of, median_step_s, resample_mean
from ..loads.summary import compute, shared_edges
from ..stop_mass import with_mass_at_stops
from ..vehicle import Vehicle
from .chain import Chain

EXPONENTS = tuple(range(3, 9))
POWER_SHARES = (0.05, 0.5, 0.95)
LOAD_NAMES = (("positive_wheel_energy_kwh_per_km", "negative_wheel_energy_kwh_per_km")
              + tuple(f"damage_equivalent_torque_range_k{k}_nm" for k in EXPONENTS)
              + tuple(f"wheel_power_exceeded_{round((1 - s) * 100)}pct_w" for s in POWER_SHARES)
              + ("speed_torque_residence_distance",))
LOAD_ALLOWANCE = np.array([0.05, 0.10] + [0.10] * len(EXPONENTS) + [0.10] * len(POWER_SHARES) + [0.25])
N_LOADS = len(LOAD_NAMES)
GATED = tuple(name for name in LOAD_NAMES if name != "speed_torque_residence_distance")
"""Load criteria a cycle should meet (`within_allowance`); the residence distance is scored only:
1800 s windows of a measured drive itself differ from the whole by about 0.15."""


def within_allowance(judged: dict) -> bool:
    """True when every `GATED` load criterion of a `judge` result is within its allowance."""
    return all(judged[name]["passed"] for name in GATED)


@dataclass
class LoadTarget:
    """The measured drive's load values and what a kernel needs to compute a walk's.

    ``resistance_n[s]`` is F_roll + F_climb + F_aero (2)–(4) of chain state ``s``, ``mass_kg[s]``
    its mass, so the wheel force of second k is m·(v_{k+1} − v_k) + F_res (1); ``measured`` the
    `LOAD_NAMES` values of the measured drive (residence distance 0), ``scale`` the deviation
    denominators; ``speed_edges_rpm``/``torque_edges_nm`` the residence bins and
    ``residence_share`` the measured time shares in them."""

    wheel_radius_m: float
    speed_mps: np.ndarray
    mass_kg: np.ndarray
    resistance_n: np.ndarray
    measured: np.ndarray
    scale: np.ndarray
    speed_edges_rpm: np.ndarray
    torque_edges_nm: np.ndarray
    residence_share: np.ndarray
    range_scale_nm: float


def measured_loads(signals: pd.DataFrame, vehicle: Vehicle) -> pd.DataFrame:
    """Wheel loads of the measured drive on a 1 s time base (window means, the acceleration from
    their speed, as `loads.collectives_of` compares a drive with a 1 Hz cycle); acceleration from the
    speed where the signals have none.

    The mass missing at stops is filled as the chain's counting fills it (`stop_mass.with_mass_at_stops`):
    a mass estimator has no estimate at standstill, and without one a stop's seconds would be left
    out of the measured loads while the chain, and so every walk, stands there."""
    frame = with_mass_at_stops(signals)
    if "accel_mps2" not in frame.columns or not np.isfinite(frame["accel_mps2"].to_numpy(float)).any():
        time = frame["time_s"].to_numpy(float)
        frame = frame.assign(accel_mps2=np.gradient(frame["speed_mps"].to_numpy(float), time)
                             if len(time) > 1 else 0.0)
    if median_step_s(frame) < 0.99:
        frame = resample_mean(frame, 1.0)
    return loads_of(frame, vehicle)


def values_of(loads: pd.DataFrame, edges: dict | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """`LOAD_NAMES` values of one drive's wheel loads (residence distance left 0), its residence
    time shares and the bins (``edges`` or the drive's own)."""
    edges = edges or shared_edges(loads)
    c = compute(loads, "drive", edges)
    power = loads["wheel_power_w"].to_numpy(float)
    durations = loads["duration_s"].to_numpy(float)
    negative_kwh = float(np.sum(np.clip(power, None, 0) * durations)) / 3.6e6
    km = c.distance_km if c.distance_km > 0 else np.nan
    values = np.array([c.positive_wheel_energy_kwh / km, negative_kwh / km]
                      + [c.damage_equivalent_torque_nm[k] for k in EXPONENTS]
                      + [c.time_quantiles["wheel_power_w"][s] for s in POWER_SHARES] + [0.0])
    total = c.residence_s.sum()
    return values, (c.residence_s / total if total > 0 else c.residence_s), edges


def load_target(signals: pd.DataFrame, vehicle: Vehicle, chain: Chain) -> LoadTarget:
    """Measured load values of ``signals`` and the per-state forces of ``chain`` for ``vehicle``."""
    loads = measured_loads(signals, vehicle)
    values, share, edges = values_of(loads)
    torque = loads["wheel_torque_nm"].to_numpy(float)
    span = float(torque.max() - torque.min()) if len(torque) else 1.0
    return target_of(values, share, edges["residence_speed_rpm"], edges["residence_torque_nm"], span, vehicle, chain)


def target_of(values: np.ndarray, share: np.ndarray, speed_edges_rpm: np.ndarray, torque_edges_nm: np.ndarray,
              torque_span_nm: float, vehicle: Vehicle, chain: Chain) -> LoadTarget:
    """The target of measured `LOAD_NAMES` ``values`` and residence time shares ``share`` on
    uniform bins (``speed_edges_rpm`` × ``torque_edges_nm``), for ``chain`` and ``vehicle``;
    ``torque_span_nm`` the measured wheel torque's span [Nm] (a scale for the rainflow kernel)."""
    scale = np.abs(values)
    scale[1] = max(scale[1], 0.1 * abs(values[0]))
    power_span = values[-2] - values[-4]
    scale[-4:-1] = np.maximum(scale[-4:-1], 0.1 * abs(power_span))
    scale[-1] = 1.0
    scale = np.where(scale > 0, scale, 1.0)
    resistance = np.asarray(road_load.resistance_force_n(chain.speed_mps, chain.gradient_pct, chain.mass_kg,
                                                         vehicle), float)
    return LoadTarget(float(vehicle.wheel_radius_m), chain.speed_mps, chain.mass_kg, resistance, values, scale,
                      np.asarray(speed_edges_rpm, float), np.asarray(torque_edges_nm, float), share,
                      max(float(torque_span_nm), 1.0))


def cycle_loads(cycle: pd.DataFrame, vehicle: Vehicle) -> pd.DataFrame:
    """Wheel loads of a generated 1 Hz cycle, as the loads stage computes them from ``cycle.csv``."""
    return loads_of(cycle, vehicle)


def evaluate_loads(cycle: pd.DataFrame, vehicle: Vehicle, target: LoadTarget) -> dict:
    """Every load criterion of ``cycle`` against the target, through the loads module (the reference
    the selection kernel is tested against)."""
    loads = cycle_loads(cycle, vehicle)
    edges = {**shared_edges(loads), "residence_speed_rpm": target.speed_edges_rpm,
             "residence_torque_nm": target.torque_edges_nm}
    values, share, _ = values_of(loads, edges)
    values[-1] = 0.5 * float(np.abs(share - target.residence_share).sum())
    return judge(values, target)


def judge(values: np.ndarray, target: LoadTarget) -> dict:
    """Deviation, allowance and plain relative deviation of each load criterion."""
    deviation = np.abs(values - target.measured) / target.scale
    deviation[-1] = values[-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = np.where(target.measured != 0, values / target.measured - 1.0, np.nan)
    return {name: {"candidate": float(v), "measured": float(m), "deviation": float(d), "allowance": float(a),
                   "relative": (float(r) if np.isfinite(r) else None), "passed": bool(d <= a)}
            for name, v, m, d, a, r in zip(LOAD_NAMES, values, target.measured, deviation, LOAD_ALLOWANCE,
                                           relative)}

