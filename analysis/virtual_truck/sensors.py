"""Sensor streams of the virtual truck, each at its own rate with its real resolution and noise.

Values are what a reader of the log computes: CAN signals quantised to their J1939 resolution
(`haulprofile.contract.j1939.SPNS`), IMU and barometer values computed from their raw register counts.
IMU axes: x forward, y left, z up (ISO 8855); the accelerometer measures specific force, so at
rest on a grade alpha it reads x = g sin(alpha), z = g cos(alpha) (eq. 7).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from haulprofile.contract import j1939

from ..road_load import G_MPS2
from .driver import friction_torque_nm

STANDARD_GRAVITY_MPS2 = 9.80665
ACCEL_FULL_SCALE_G = 4
GYRO_FULL_SCALE_DPS = 245
ACCEL_SCALE_MPS2_PER_LSB = 0.122e-3 * STANDARD_GRAVITY_MPS2
"""LSM9DS1 linear acceleration sensitivity at +-4 g: 0.122 mg/LSB (datasheet Table 3)."""
GYRO_SCALE_RADPS_PER_LSB = 8.75e-3 * np.pi / 180.0
"""LSM9DS1 angular rate sensitivity at +-245 dps: 8.75 mdps/LSB."""
IDEAL_IMU_TEMPERATURE_C = 25.0
"""The IMU die's temperature in the ideal world, which does not warm up (the realistic levels'
warm-up: `sensor_errors.imu_temperature_c`)."""

BARO_PA_PER_LSB = 100.0 / 4096.0
"""LPS25HB PRESS_OUT: 4096 LSB/hPa."""
HTS221_CALIBRATION = {"h0_rh_pct": 33.0, "h1_rh_pct": 75.5, "h0_out": -3528, "h1_out": 6234,
                      "t0_c": 11.0, "t1_c": 36.5, "t0_out": -240, "t1_out": 795}
"""Factory calibration of the emulated HTS221 (linear: value = v0 + (raw - out0) (v1 - v0)/(out1 - out0))."""

SEA_LEVEL_PA = 101_325.0
FUEL_G_PER_KWH = 205.0
DIESEL_KG_PER_L = 0.835
IDLE_FUEL_LPH = 1.6


def pressure_at_height_pa(height_m, sea_level_pa=SEA_LEVEL_PA):
    """Equation (6) solved for pressure [Pa]: p = p0 (1 - h / 44330.8)^5.255."""
    return sea_level_pa * (1.0 - np.asarray(height_m) / 44330.8) ** 5.255


def _times(duration_s: float, rate_hz: float, phase_s: float) -> np.ndarray:
    return np.arange(phase_s, duration_s, 1.0 / rate_hz)


def _sample(states: pd.DataFrame, column: str, times: np.ndarray) -> np.ndarray:
    """Linear interpolation of a 100 Hz state at sensor times."""
    return np.interp(times, states["time_s"].to_numpy(), states[column].to_numpy(float))


def _held(states: pd.DataFrame, column: str, times: np.ndarray) -> np.ndarray:
    """The last state at or before each time (for discrete signals)."""
    index = np.searchsorted(states["time_s"].to_numpy(), times, side="right") - 1
    return states[column].to_numpy()[np.clip(index, 0, len(states) - 1)]


def _quantise(values, resolution: float, offset: float = 0.0) -> np.ndarray:
    return np.round((np.asarray(values) - offset) / resolution) * resolution + offset


def _gauss_markov(rng, n: int, time_constant_steps: float) -> np.ndarray:
    """Unit-variance first-order Gauss-Markov (AR(1)) sequence."""
    phi = np.exp(-1.0 / time_constant_steps)
    noise = rng.standard_normal(n) * np.sqrt(1 - phi * phi)
    out = np.empty(n)
    state = rng.standard_normal()
    for k in range(n):
        state = phi * state + noise[k]
        out[k] = state
    return out


def parasitic_torque_nm(states, times: np.ndarray, compressor_gain: float = 1.0, fan_gain: float = 1.0) -> np.ndarray:
    """What the engine controller takes its accessories' torque to be [Nm]: it switches the
    compressor and the fan itself, and scales what each takes by its own model (``*_gain``, 1 =
    exact). The PTO is the body builder's and not in it."""
    if "aux_compressor_torque_nm" not in states:
        return np.zeros(times.shape)
    return (compressor_gain * _held(states, "aux_compressor_torque_nm", times)
            + fan_gain * _held(states, "aux_fan_torque_nm", times))


def report_indicated_torque(engine_stream: pd.DataFrame, states, vehicle) -> dict:
    """Turn EEC1's torque report (SPN 513) into J1939-71's own form, the indicated torque: the
    friction EEC3 sends (SPN 514, same rounding) added, never below zero, and exactly 0 % in a fuel
    cut (no fuel, no torque to model, whatever the report's error under load). The real idling
    CANedge recording's engine reports so (6.6-7.4 % at idle with 5 % friction)."""
    ref = vehicle.engine_reference_torque_nm
    t = engine_stream["time_s"].to_numpy()
    friction = friction_torque_nm(_held(states, "engine_speed_rpm", t), vehicle)
    fuel_cut = _held(states, "fuel_cut", t)
    indicated = np.clip(engine_stream["actual_engine_torque_pct"] + np.round(friction / ref * 100), 0, 125)
    engine_stream["actual_engine_torque_pct"] = np.where(fuel_cut, 0.0, indicated)
    return {"torque_report": "indicated"}


def engine_losses(states, vehicle, times: np.ndarray) -> pd.DataFrame:
    """EEC3 (4 Hz): the nominal friction (SPN 514), the engine's motoring torque at its speed, the
    one the simulation drags the truck with, so that the torque report (SPN 513, net of it) and the
    friction add up to the indicated torque; and the accessories' torque (SPN 2978) as the engine
    controller estimates it; both in 1 % of the reference torque."""
    ref = vehicle.engine_reference_torque_nm
    friction = friction_torque_nm(_held(states, "engine_speed_rpm", times), vehicle)
    return pd.DataFrame({"time_s": times,
                         "nominal_friction_torque_pct": np.clip(np.round(friction / ref * 100), -125, 125),
                         "parasitic_loss_torque_pct": np.clip(np.round(parasitic_torque_nm(states, times) / ref * 100),
                                                              -125, 125)})


def can_streams(states, vehicle, sensors, rng) -> dict:
    duration = float(states["time_s"].iloc[-1])
    ref = vehicle.engine_reference_torque_nm
    spn = j1939.SPNS
    out = {}
    t = _times(duration, 10.0, 0.004)
    kmh = np.maximum(_sample(states, "speed_mps", t) * 3.6 + rng.normal(0, sensors.wheel_speed_noise_kmh, t.size)
                     * (_sample(states, "speed_mps", t) > 0.3), 0.0)
    kmh = _quantise(kmh, spn["wheel_speed_kmh"].resolution)
    out["wheel_speed"] = pd.DataFrame({"time_s": t, "wheel_speed_kmh": kmh, "speed_mps": kmh / 3.6,
                                       "brake_switch": _held(states, "brake_active", t).astype(np.int8)})
    t = _times(duration, 100.0, 0.002)
    rpm = _sample(states, "engine_speed_rpm", t) + rng.normal(0, sensors.engine_speed_noise_rpm, t.size)
    torque_pct = _held(states, "engine_torque_nm", t) / ref * 100 + rng.normal(0, sensors.engine_torque_noise_pct, t.size)
    demand_pct = _held(states, "driver_demand_torque_nm", t) / ref * 100
    out["engine"] = pd.DataFrame({
        "time_s": t,
        "engine_speed_rpm": _quantise(np.clip(rpm, 0, 8031), spn["engine_speed_rpm"].resolution),
        "actual_engine_torque_pct": np.clip(np.round(torque_pct), -125, 125),
        "driver_demand_torque_pct": np.clip(np.round(demand_pct), -125, 125)})
    out["engine_losses"] = engine_losses(states, vehicle, _times(duration, 4.0, 0.012))
    t = _times(duration, 10.0, 0.006)
    out["transmission"] = pd.DataFrame({"time_s": t, "current_gear": _held(states, "gear", t).astype(np.int16)})
    t = _times(duration, 20.0, 0.008)
    full = np.maximum(_held(states, "full_load_torque_nm", t), 1.0)
    pedal = np.clip(_held(states, "driver_demand_torque_nm", t) / full * 100, 0, 100)
    out["pedals"] = pd.DataFrame({"time_s": t, "accelerator_pedal_pct": _quantise(pedal, spn["accelerator_pedal_pct"].resolution),
                                  "brake_switch": _held(states, "brake_active", t).astype(np.int8)})
    t = _times(duration, 1.0, 0.5)
    power_kw = np.maximum(_sample(states, "engine_torque_nm", t) * _sample(states, "engine_speed_rpm", t)
                          * np.pi / 30 / 1000, 0.0)
    fuel = IDLE_FUEL_LPH + power_kw * FUEL_G_PER_KWH / 1000 / DIESEL_KG_PER_L
    out["fuel"] = pd.DataFrame({"time_s": t, "fuel_rate_lph": _quantise(fuel, spn["fuel_rate_lph"].resolution)})
    t = _times(duration, 1.0, 0.7)
    mass = _held(states, "mass_kg", t)
    standing = _held(states, "stop", t).astype(int)
    segment = np.concatenate([[0], np.cumsum(np.diff(standing) == 1)])
    bias = rng.uniform(-1, 1, segment.max() + 1) * sensors.weight_bias_pct / 100
    weight = mass * (1 + bias[segment]) + rng.normal(0, 30.0, t.size)
    out["weight"] = pd.DataFrame({"time_s": t, "gross_combination_weight_kg": _quantise(
        weight, spn["gross_combination_weight_kg"].resolution)})
    return out


def imu_stream(states, sensors, rng) -> pd.DataFrame:
    duration = float(states["time_s"].iloc[-1])
    t = _times(duration, sensors.imu_rate_hz, 0.001)
    v = _sample(states, "speed_mps", t)
    alpha = np.arctan(_sample(states, "gradient_pct", t) / 100)
    kappa = _sample(states, "curvature_per_m", t)
    grid_alpha = np.arctan(states["gradient_pct"].to_numpy() / 100)
    pitch_rate = np.interp(t, states["time_s"].to_numpy(), np.gradient(grid_alpha, states["time_s"].to_numpy()))
    specific = np.column_stack([_sample(states, "accel_mps2", t) + G_MPS2 * np.sin(alpha),
                                v * v * kappa, G_MPS2 * np.cos(alpha)])
    rates = np.column_stack([np.zeros_like(t), -pitch_rate, v * kappa])
    accel_bias = rng.normal(0, sensors.imu_accel_bias_mps2, 3)
    gyro_bias = rng.normal(0, sensors.imu_gyro_bias_radps, 3)
    specific += accel_bias + rng.normal(0, sensors.imu_accel_noise_mps2, specific.shape)
    rates += gyro_bias + rng.normal(0, sensors.imu_gyro_noise_radps, rates.shape)
    accel_raw = np.clip(np.round(specific / ACCEL_SCALE_MPS2_PER_LSB), -32768, 32767).astype(np.int16)
    gyro_raw = np.clip(np.round(rates / GYRO_SCALE_RADPS_PER_LSB), -32768, 32767).astype(np.int16)
    frame = {"time_s": t}
    for j, axis in enumerate("xyz"):
        frame[f"accel_{axis}_raw"] = accel_raw[:, j]
    for j, axis in enumerate("xyz"):
        frame[f"gyro_{axis}_raw"] = gyro_raw[:, j]
    for j, axis in enumerate("xyz"):
        frame[f"accel_{axis}_mps2"] = accel_raw[:, j] * ACCEL_SCALE_MPS2_PER_LSB
    for j, axis in enumerate("xyz"):
        frame[f"gyro_{axis}_radps"] = gyro_raw[:, j] * GYRO_SCALE_RADPS_PER_LSB
    frame["imu_temperature_c"] = np.full(t.size, IDEAL_IMU_TEMPERATURE_C)
    return pd.DataFrame(frame)


def weather(states, sensors, rng):
    """Sea-level pressure [Pa] (weather drift) and air temperature [degC] at the 100 Hz states."""
    t = states["time_s"].to_numpy()
    hours = t / 3600.0
    drift = rng.choice([-1.0, 1.0]) * sensors.baro_drift_pa_per_h * hours
    wobble = 30.0 * np.sin(2 * np.pi * hours / rng.uniform(0.5, 1.5) + rng.uniform(0, 2 * np.pi))
    sea_level = SEA_LEVEL_PA + rng.uniform(-1500, 1500) + drift + wobble
    air = rng.uniform(5, 25) - 0.0065 * states["road_height_m"].to_numpy() + 1.5 * np.sin(2 * np.pi * hours / 3)
    return sea_level, air


def environment_streams(states, sensors, rng) -> dict:
    duration = float(states["time_s"].iloc[-1])
    sea_level, air = weather(states, sensors, rng)
    time = states["time_s"].to_numpy()
    t = _times(duration, 25.0, 0.003)
    p = pressure_at_height_pa(np.interp(t, time, states["road_height_m"].to_numpy()) + 1.5,
                              np.interp(t, time, sea_level)) + rng.normal(0, sensors.baro_noise_pa, t.size)
    temp = np.interp(t, time, air) + 8.0 + rng.normal(0, 0.05, t.size)
    p_raw = np.round(p / 100.0 * 4096).astype(np.int64)
    t_raw = np.round((temp - 42.5) * 480).astype(np.int64)
    baro = pd.DataFrame({"time_s": t, "pressure_pa": p_raw * BARO_PA_PER_LSB, "temperature_c": 42.5 + t_raw / 480.0,
                         "pressure_raw": p_raw, "temperature_raw": t_raw})
    t = _times(duration, 12.5, 0.011)
    cal = HTS221_CALIBRATION
    rh = np.clip(55 + 12 * np.sin(2 * np.pi * t / 5400 + rng.uniform(0, 6.3)) + rng.normal(0, 0.3, t.size), 0, 100)
    temp = np.interp(t, time, air) + 8.0 + rng.normal(0, 0.1, t.size)
    h_raw = np.round(cal["h0_out"] + (rh - cal["h0_rh_pct"]) * (cal["h1_out"] - cal["h0_out"])
                     / (cal["h1_rh_pct"] - cal["h0_rh_pct"])).astype(np.int64)
    t_raw = np.round(cal["t0_out"] + (temp - cal["t0_c"]) * (cal["t1_out"] - cal["t0_out"])
                     / (cal["t1_c"] - cal["t0_c"])).astype(np.int64)
    humidity = pd.DataFrame({
        "time_s": t,
        "relative_humidity_pct": cal["h0_rh_pct"] + (h_raw - cal["h0_out"]) * (cal["h1_rh_pct"] - cal["h0_rh_pct"])
        / (cal["h1_out"] - cal["h0_out"]),
        "temperature_c": cal["t0_c"] + (t_raw - cal["t0_out"]) * (cal["t1_c"] - cal["t0_c"]) / (cal["t1_out"] - cal["t0_out"]),
        "humidity_raw": h_raw, "temperature_raw": t_raw})
    return {"barometer": baro, "humidity": humidity}


def gps_stream(states, road, sensors, rng) -> pd.DataFrame:
    """Fixes at ``gps_rate_hz``; accuracy collapses inside tunnels: tens of metres near the
    portals, no fix more than 120 m inside."""
    duration = float(states["time_s"].iloc[-1])
    t = _times(duration, sensors.gps_rate_hz, 0.0)
    distance = _sample(states, "distance_m", t)
    depth_in = road.at(road.tunnel_depth_in_m, distance)
    inside = road.at(road.in_tunnel.astype(float), distance) > 0.5
    degrade = np.where(inside, 1.0 + depth_in / 4.0, 1.0)
    h_acc = sensors.gps_h_acc_m * degrade * rng.uniform(0.9, 1.1, t.size)
    h_acc = np.where(inside, np.maximum(h_acc, 20.0), h_acc)
    v_acc = sensors.gps_v_acc_m / sensors.gps_h_acc_m * h_acc
    steps_per_30s = 30.0 * sensors.gps_rate_hz
    east = road.at(road.east_m, distance) + 0.7 * h_acc * _gauss_markov(rng, t.size, steps_per_30s)
    north = road.at(road.north_m, distance) + 0.7 * h_acc * _gauss_markov(rng, t.size, steps_per_30s)
    lat, lon = road.latlon(east, north)
    altitude = _sample(states, "road_height_m", t) + 1.0 * v_acc * _gauss_markov(rng, t.size, steps_per_30s)
    speed = np.maximum(_sample(states, "speed_mps", t) + rng.normal(0, 0.05, t.size) * degrade, 0.0)
    fix = ~(inside & (depth_in > 120.0))
    satellites = np.where(inside, np.maximum(4, 12 - (depth_in // 20)), rng.integers(9, 15, t.size))
    return pd.DataFrame({
        "time_s": t, "fix_quality": fix.astype(np.int8),
        "latitude_deg": np.where(fix, lat, np.nan), "longitude_deg": np.where(fix, lon, np.nan),
        "altitude_m": np.where(fix, altitude, np.nan), "h_acc_m": np.where(fix, h_acc, np.nan),
        "v_acc_m": np.where(fix, v_acc, np.nan), "speed_mps": np.where(fix, speed, np.nan),
        "satellites": np.where(fix, satellites, 0).astype(np.int16)})


def make_sensors(states, road, scenario, vehicle, rng) -> dict:
    """All streams (see `analysis.virtual_truck.VirtualDrive`)."""
    sensors = scenario.sensors
    streams = can_streams(states, vehicle, sensors, rng)
    streams["imu"] = imu_stream(states, sensors, rng)
    streams.update(environment_streams(states, sensors, rng))
    streams["gps"] = gps_stream(states, road, sensors, rng)
    streams["engine_reference_torque_nm"] = float(vehicle.engine_reference_torque_nm)
    return streams
