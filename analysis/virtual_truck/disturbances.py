"""What the realistic levels add to the truck's physics: wind with gusts, a trailer change at a
stop, a driveline whose efficiency depends on gear and load, and auxiliary loads (air compressor,
cooling fan, PTO) that take engine torque without moving the truck where the engine burns fuel,
and brake it where the engine is in a fuel cut (the wheels drive them then)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..runs import true_runs
from .driver import FAN_RATED_RPM, friction_torque_nm
from .realism import Realism
from .road import Road

GUST_LENGTH_M = 150.0
"""Gusts change over about this distance of travel."""


def head_wind_mps(road: Road, level: Realism, rng: np.random.Generator,
                  gust_rng: np.random.Generator | None = None) -> tuple[np.ndarray, dict]:
    """Wind component against the direction of travel [m/s] on the road's 1 m grid: a mean wind
    of random direction seen along the curving road, plus gusts (Gauss-Markov over distance).
    ``gust_rng``: the gusts drawn from it instead, the mean wind and every later draw of ``rng``
    as without it (the same drive under another draw of its gusts: their bias told from their
    spread)."""
    if level.wind_mps <= 0 and level.wind_gust_mps <= 0:
        return np.zeros(road.distance_m.shape), {}
    speed = level.wind_mps * rng.uniform(0.5, 1.5)
    towards = rng.uniform(0, 2 * np.pi)
    heading = np.arctan2(np.gradient(road.north_m), np.gradient(road.east_m))
    head = -speed * np.cos(towards - heading)
    phi = np.exp(-(road.distance_m[1] - road.distance_m[0]) / GUST_LENGTH_M)
    gust = _gusts(road.distance_m.size, phi, rng)
    if gust_rng is not None:
        gust = _gusts(road.distance_m.size, phi, gust_rng)
    return head + level.wind_gust_mps * gust, {"wind_speed_mps": speed, "wind_towards_deg": float(np.degrees(towards)),
                                               "wind_gust_sigma_mps": level.wind_gust_mps}


def _gusts(size: int, phi: float, rng: np.random.Generator) -> np.ndarray:
    """A unit-variance first-order Gauss-Markov series of ``size`` steps, ``phi`` per step."""
    noise = rng.standard_normal(size) * np.sqrt(1 - phi * phi)
    gust = np.empty_like(noise)
    state = rng.standard_normal()
    for k in range(noise.size):  # ~1e5 steps, once per drive
        state = phi * state + noise[k]
        gust[k] = state
    return gust


def trailer_change(after_kg: np.ndarray, stop_duration_s: np.ndarray, curb_kg: float, max_payload_kg: float | None,
                   rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Total mass after each stop with the trailer (or load) swapped at the longest stop before
    the final one: the payload from there on changes by the difference to the new one."""
    if len(after_kg) < 2:
        return after_kg, {}
    j = int(np.argmax(stop_duration_s[:-1]))
    payload = after_kg[j] - curb_kg
    limit = max_payload_kg if max_payload_kg is not None else max(2 * payload, 10_000.0)
    new = rng.uniform(0.2, 0.95) * limit
    out = after_kg.copy()
    out[j:] = np.clip(out[j:] + new - payload, curb_kg, curb_kg + limit)
    return out, {"trailer_change_stop": j + 1, "trailer_change_payload_kg": [float(payload), float(new)]}


def _on_periods(rng, time_s: np.ndarray, per_hour: float, low_s: float, high_s: float) -> np.ndarray:
    on = np.zeros(time_s.shape, bool)
    duration = time_s[-1] - time_s[0]
    for start in rng.uniform(time_s[0], time_s[-1], rng.poisson(per_hour * duration / 3600.0)):
        on |= (time_s >= start) & (time_s < start + rng.uniform(low_s, high_s))
    return on


@dataclass(frozen=True)
class Accessories:
    """What sits between the engine and the gearbox: the compressor's power and the fan's rated
    power per simulation step [W] while each runs (none after the arrays end), the driveline's
    efficiency per gear and its spin loss at the gearbox input [Nm]."""

    compressor_w: np.ndarray
    fan_rated_w: np.ndarray
    gear_efficiency: np.ndarray
    spin_loss_nm: float

    @classmethod
    def none(cls, vehicle) -> "Accessories":
        """No accessories and a driveline as nominal (the `ideal` truck)."""
        return cls(np.zeros(0), np.zeros(0), np.full(len(vehicle.total_ratios), vehicle.driveline_efficiency), 0.0)


def accessories_schedule(first: pd.DataFrame, vehicle, level: Realism, rng: np.random.Generator) -> Accessories:
    """When the compressor and the fan run, from a first pass of the drive without them: the
    compressor cycles by time, the fan runs when the engine has been hot (the gearbox torque above
    60 % of the reference for most of the last minute) and a few random times an hour."""
    torque = first["engine_torque_nm"].to_numpy()
    time_s = first["time_s"].to_numpy()
    ref = vehicle.engine_reference_torque_nm
    compressor = _on_periods(rng, time_s, 12.0, 15.0, 60.0) * level.aux_compressor_kw * 1000.0
    hot = pd.Series(torque > 0.6 * ref).rolling(6000, min_periods=1).mean().to_numpy() > 0.5
    fan = (hot | _on_periods(rng, time_s, 2.0, 60.0, 180.0)) * level.aux_fan_kw * 1000.0
    top = len(vehicle.total_ratios)
    gears = np.arange(top)
    eta = vehicle.driveline_efficiency + level.driveline_gear_spread * (gears / max(top - 1, 1) - 0.5)
    return Accessories(compressor, fan, eta, level.driveline_spin_loss_pct / 100.0 * ref)


def _per_step(schedule: np.ndarray, n: int) -> np.ndarray:
    """A schedule cut or padded with zeros (off) to ``n`` steps."""
    out = np.zeros(n)
    out[: min(n, schedule.size)] = schedule[:n]
    return out


def engine_loads(states: pd.DataFrame, vehicle, level: Realism, accessories: Accessories) -> tuple[dict, dict]:
    """Engine torque [Nm] the driveline and the accessories really take, from the torque the
    simulation put through the gearbox with the nominal efficiency: where the engine burns fuel it
    makes the accessories' and the driveline's losses on top; in a fuel cut its net torque is its
    friction (the wheels drive the rest). Columns for the states and the injected sizes."""
    torque = states["engine_torque_nm"].to_numpy()
    gear = states["gear"].to_numpy()
    rpm = states["engine_speed_rpm"].to_numpy()
    time_s = states["time_s"].to_numpy()
    fuel_cut = states["fuel_cut"].to_numpy()
    eta = vehicle.driveline_efficiency
    engaged = gear > 0
    eta_gear = np.where(engaged, accessories.gear_efficiency[np.maximum(gear, 1) - 1], eta)
    factor = np.where(torque >= 0, eta / eta_gear, eta_gear / eta)
    spin = np.where(engaged, accessories.spin_loss_nm, 0.0)
    driveline = np.where(engaged, torque * factor + spin, torque)
    omega = np.maximum(rpm, 1.0) * np.pi / 30.0
    compressor = _per_step(accessories.compressor_w, len(states))
    fan = _per_step(accessories.fan_rated_w, len(states)) * (rpm / FAN_RATED_RPM) ** 3
    standing = states["stop"].to_numpy()
    pto = np.zeros(time_s.shape)
    if level.aux_pto_kw > 0:
        for start, end in true_runs(standing):
            if time_s[end - 1] - time_s[start] >= 120.0 and start > 0:
                middle = slice(start + (end - start) // 4, start + 3 * (end - start) // 4)
                pto[middle] = level.aux_pto_kw * 1000.0
    aux = (compressor + fan + pto) / omega
    engine = driveline + aux
    engine[fuel_cut] = -friction_torque_nm(rpm[fuel_cut], vehicle)
    columns = {"engine_torque_nm": engine, "wheel_engine_torque_nm": torque, "aux_torque_nm": aux,
               "aux_compressor_torque_nm": compressor / omega, "aux_fan_torque_nm": fan / omega,
               "driveline_efficiency": eta_gear}
    sizes = {"aux_compressor_on_share": float(np.mean(compressor > 0)), "aux_fan_on_share": float(np.mean(fan > 0)),
             "aux_pto_on_s": float(np.sum(pto > 0) * (time_s[1] - time_s[0])),
             "driveline_gear_spread": level.driveline_gear_spread,
             "driveline_spin_loss_nm": accessories.spin_loss_nm}
    return columns, sizes
