"""Sensor errors of the realistic levels, applied to the ideal streams of `sensors.make_sensors`
(sizes from `realism.Realism`, sources in ``docs/virtual-truck.md``): wheel-speed scale (tyre wear
and pressure), engine torque report gain and offset, IMU mounting pitch and temperature drift,
barometric weather front and cab pressure transients, GPS multipath in towns and outages."""

from __future__ import annotations

import numpy as np
import pandas as pd

from haulprofile.contract import j1939

from .realism import Realism
from .road import Road
from .sensors import (ACCEL_SCALE_MPS2_PER_LSB, BARO_PA_PER_LSB, _gauss_markov, _held, _quantise, _sample,
                      parasitic_torque_nm)

IMU_WARM_UP_K = 15.0
IMU_WARM_UP_S = 1800.0


def _sign(rng) -> float:
    return float(rng.choice([-1.0, 1.0]))


def wheel_speed(stream: pd.DataFrame, states, level: Realism, sensors, rng) -> dict:
    scale = rng.uniform(-1.0, 1.0) * level.wheel_scale_pct / 100.0
    t = stream["time_s"].to_numpy()
    true = _sample(states, "speed_mps", t)
    noise = rng.normal(0, sensors.wheel_speed_noise_kmh, t.size) * (true > 0.3)
    kmh = np.maximum(true * 3.6 * (1 + scale) + noise, 0.0)
    kmh = _quantise(kmh, j1939.SPNS["wheel_speed_kmh"].resolution)
    stream["wheel_speed_kmh"], stream["speed_mps"] = kmh, kmh / 3.6
    return {"wheel_speed_scale": scale}


def engine_torque(stream: pd.DataFrame, states, reference_nm: float, level: Realism, sensors, rng) -> dict:
    gain = rng.uniform(-1.0, 1.0) * level.torque_gain_pct / 100.0
    offset = rng.uniform(-1.0, 1.0) * level.torque_offset_pct
    t = stream["time_s"].to_numpy()
    pct = (_held(states, "engine_torque_nm", t) / reference_nm * 100 * (1 + gain) + offset
           + rng.normal(0, sensors.engine_torque_noise_pct, t.size))
    stream["actual_engine_torque_pct"] = np.clip(np.round(pct), -125, 125)
    return {"torque_report_gain": gain, "torque_report_offset_pct": offset}


def parasitic_estimate(stream: pd.DataFrame, states, reference_nm: float, level: Realism, rng) -> dict:
    """SPN 2978 with the engine controller's own error: per drive, its model of what the compressor
    and the fan take is off by a factor each (it knows when they run, not exactly what they take);
    or a constant 0 % or not available (NaN), as some engines send it."""
    gains = 1.0 + rng.uniform(-1.0, 1.0, 2) * level.parasitic_estimate_error_pct / 100.0
    t = stream["time_s"].to_numpy()
    pct = np.clip(np.round(parasitic_torque_nm(states, t, *gains) / reference_nm * 100), -125, 125)
    if level.parasitic_report == "zero":
        pct = np.zeros(t.size)
    elif level.parasitic_report == "not available":
        pct = np.full(t.size, np.nan)
    stream["parasitic_loss_torque_pct"] = pct
    return {"parasitic_compressor_gain": float(gains[0]), "parasitic_fan_gain": float(gains[1]),
            "parasitic_report": level.parasitic_report}


def imu_temperature_c(time_s: np.ndarray, start_c: float) -> np.ndarray:
    """The IMU's temperature [degC]: the cab warms up after the start."""
    return start_c + IMU_WARM_UP_K * (1.0 - np.exp(-time_s / IMU_WARM_UP_S))


def imu(stream: pd.DataFrame, level: Realism, rng) -> dict:
    pitch = _sign(rng) * rng.uniform(0.5, 1.0) * np.radians(level.imu_mount_pitch_deg)
    start_c = rng.uniform(0.0, 25.0)
    drift = rng.uniform(-1.0, 1.0, 3) * level.imu_temp_drift_mps2_per_k
    t = stream["time_s"].to_numpy()
    warm = (imu_temperature_c(t, start_c) - start_c)[:, None] * drift[None, :]
    x, y, z = (stream[f"accel_{a}_mps2"].to_numpy() for a in "xyz")
    rotated = np.column_stack([x * np.cos(pitch) + z * np.sin(pitch), y, -x * np.sin(pitch) + z * np.cos(pitch)]) + warm
    raw = np.clip(np.round(rotated / ACCEL_SCALE_MPS2_PER_LSB), -32768, 32767).astype(np.int16)
    for j, axis in enumerate("xyz"):
        stream[f"accel_{axis}_raw"] = raw[:, j]
        stream[f"accel_{axis}_mps2"] = raw[:, j] * ACCEL_SCALE_MPS2_PER_LSB
    stream["imu_temperature_c"] = imu_temperature_c(t, start_c)
    return {"imu_mount_pitch_deg": float(np.degrees(pitch)), "imu_start_temperature_c": start_c,
            "imu_temp_drift_mps2_per_k": drift.tolist()}


def cab_pressure_pa(time_s: np.ndarray, standing: np.ndarray, size_pa: float, rng) -> np.ndarray:
    """Cab overpressure [Pa]: the ventilation blower's level changes every 3-15 minutes (0 to
    ``size_pa``), the door opens at stops (overpressure gone, then a slam spike), first-order lag 3 s."""
    level = np.zeros(time_s.shape)
    at = 0.0
    while at < time_s[-1]:
        step = rng.uniform(180.0, 900.0)
        level[(time_s >= at) & (time_s < at + step)] = rng.uniform(0.0, size_pa)
        at += step
    level[standing] = 0.0
    edges = np.flatnonzero(np.diff(standing.astype(np.int8)) == -1)
    for k in edges:
        level[(time_s >= time_s[k] - 1.0) & (time_s < time_s[k])] += 2.0 * size_pa
    dt = np.diff(time_s, prepend=time_s[0])
    out = np.empty_like(level)
    state = level[0]
    for k in range(level.size):  # once per drive
        state += (level[k] - state) * min(dt[k] / 3.0, 1.0)
        out[k] = state
    return out


def barometer(stream: pd.DataFrame, states, level: Realism, rng) -> dict:
    t = stream["time_s"].to_numpy()
    duration = t[-1]
    centre = rng.uniform(0.2, 0.8) * duration
    width = rng.uniform(0.5, 1.5) * 3600.0
    front = _sign(rng) * level.baro_front_pa * 0.5 * (1 + np.tanh((t - centre) / width))
    state_t = states["time_s"].to_numpy()
    cab = np.interp(t, state_t, cab_pressure_pa(state_t, states["stop"].to_numpy(), level.baro_cab_transient_pa, rng))
    p = stream["pressure_pa"].to_numpy() + front + cab
    raw = np.round(p / BARO_PA_PER_LSB).astype(np.int64)
    stream["pressure_raw"], stream["pressure_pa"] = raw, raw * BARO_PA_PER_LSB
    return {"baro_front_pa": float(front[-1] - front[0]), "baro_front_centre_s": float(centre),
            "baro_cab_pa_max": float(np.max(np.abs(cab)))}


def gps(stream: pd.DataFrame, road: Road, states, level: Realism, rng) -> dict:
    """Multipath in towns (accuracy worse by ``gps_urban_factor``, errors correlated over 5 s) and
    outages outside tunnels (``gps_outages_per_h``, 20-120 s each)."""
    t = stream["time_s"].to_numpy()
    rate = 1.0 / np.median(np.diff(t))
    outage = np.zeros(t.size, bool)
    for start in rng.uniform(0, t[-1], rng.poisson(level.gps_outages_per_h * t[-1] / 3600.0)):
        outage |= (t >= start) & (t < start + rng.uniform(20.0, 120.0))
    distance = _sample(states, "distance_m", t)
    east, north = road.at(road.east_m, distance), road.at(road.north_m, distance)
    town = road.town.at(east, north) if road.town is not None else np.zeros(t.size)
    factor = 1.0 + town * max(level.gps_urban_factor - 1.0, 0.0)
    h_acc = stream["h_acc_m"].to_numpy() * factor
    v_acc = stream["v_acc_m"].to_numpy() * factor
    extra = np.sqrt(np.maximum(factor ** 2 - 1.0, 0.0)) * 0.7 * stream["h_acc_m"].to_numpy()
    de = extra * _gauss_markov(rng, t.size, 5.0 * rate)
    dn = extra * _gauss_markov(rng, t.size, 5.0 * rate)
    e, n = road.local(stream["latitude_deg"].to_numpy(), stream["longitude_deg"].to_numpy())
    lat, lon = road.latlon(e + de, n + dn)
    altitude = stream["altitude_m"].to_numpy() + 1.5 * extra * _gauss_markov(rng, t.size, 5.0 * rate)
    fix = (stream["fix_quality"].to_numpy() > 0) & ~outage
    stream["fix_quality"] = fix.astype(np.int8)
    for column, values in (("latitude_deg", lat), ("longitude_deg", lon), ("altitude_m", altitude),
                           ("h_acc_m", h_acc), ("v_acc_m", v_acc), ("speed_mps", stream["speed_mps"].to_numpy())):
        stream[column] = np.where(fix, values, np.nan)
    stream["satellites"] = np.where(fix, stream["satellites"].to_numpy(), 0).astype(np.int16)
    return {"gps_outage_s": float(outage.sum() / rate), "gps_urban_share": float(np.mean(town > 0.5))}


def apply_sensor_errors(streams: dict, states, road: Road, sensors, level: Realism, rng) -> dict:
    """Apply the level's sensor errors to the streams in place (``sensors``: the scenario's noise
    levels); return the injected sizes. Each sensor draws from its own generator spawned from
    ``rng``, its sizes before its noise, so a drive that lasts a step longer or shorter (a change of
    the truck's physics) keeps every drawn size: a before/after of the matrix compares like drives."""
    wheel, torque, inertial, pressure, satellite, parasitic = rng.spawn(6)
    reference_nm = streams["engine_reference_torque_nm"]
    injected = {}
    injected |= wheel_speed(streams["wheel_speed"], states, level, sensors, wheel)
    injected |= engine_torque(streams["engine"], states, reference_nm, level, sensors, torque)
    injected |= imu(streams["imu"], level, inertial)
    injected |= barometer(streams["barometer"], states, level, pressure)
    injected |= gps(streams["gps"], road, states, level, satellite)
    injected |= parasitic_estimate(streams["engine_losses"], states, reference_nm, level, parasitic)
    return injected
