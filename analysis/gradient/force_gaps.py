"""The force balance over the stretches its 1-s window cannot span: across gear shifts, and as an
upper bound across short brake applications (issue 26, `gps+can` on urban drives).

The virtual accelerometer (`force_balance.virtual_accelerometer_mps2`) compares the wheel force
with dv/dt through a centred 1-s mean, so its data filter drops every sample within a second of a
shift or a brake reading. On the matrix's urban drives 68-92 % of the gradient's squared error sat
in the bins this left without a force-balance sample. Yet while the clutch is open the force on
the wheels is known: none at all where the gearbox reports no gear engaged (J1939 ETC2 current
gear 0: the engine's torque does not reach the wheels, whatever its report's gain and offset), and
the engine's through the gear where engine speed over wheel speed is a gear's ratio. Integrated
over a window W of samples of known force, Newton's law gives

    g sin(alpha) = (1/T) ∫_W (F_wheel - F_aero) / m dt - g c_r - (v_end - v_start) / T

with T the window's length: the accelerometer's reading less dv/dt, which is what the smoother
takes from an accelerometer. W is the 1-s window nearest the sample within its stretch, or the
whole stretch where that is shorter. Its noise is the wheel speed's at the two ends,
sqrt(2) sigma_v / T (sigma_v from the wheel speed's own second differences), and where W holds a
change between clutch open and closed, the one sample whose force may belong to either side,
|F| dt / (m T). The brake switch is read once per sample and the brake acts unseen between
readings, so the windows keep the data filter's margin from them; spanning them with the engine's
force alone, the same sum is an upper bound (the brakes only take force away).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..engine_torque import driveline_torque_nm, knows_engine_drag
from ..kinematics import sample_step_s
from ..road_load import G_MPS2, aero_force_n, wheel_force_from_torque_n, wheel_torque_from_engine_nm
from ..runs import true_runs, widened
from .engine_drag import in_gear

WINDOW_S = 1.0
"""The window [s] of the force balance's centred mean (the kinematics stage's acceleration)."""
MIN_SAMPLES = 3
"""Fewest samples of a window: two intervals, so that v_end - v_start spans more than one step."""


def wheel_speed_noise_mps(speed_mps: np.ndarray, moving_mps: float) -> float:
    """1-sigma [m/s] of the wheel speed's white noise (its resolution and the sensor's jitter) from
    its second differences where the truck moves: v[k+1] - 2 v[k] + v[k-1] has 6 sigma² from
    the noise and, at 10 Hz, little from the acceleration's change; robust (MAD) against shifts."""
    speed = np.asarray(speed_mps, dtype=float)
    second = speed[2:] - 2 * speed[1:-1] + speed[:-2]
    moving = (speed[1:-1] > moving_mps) & np.isfinite(second)
    if moving.sum() < 10:
        return float("nan")
    return float(1.4826 * np.median(np.abs(second[moving])) / np.sqrt(6))


def clutch_open(frame: pd.DataFrame) -> np.ndarray:
    """Samples where the gearbox reports no gear engaged (``current_gear`` 0): the engine does not
    drive the wheels."""
    if "current_gear" not in frame.columns:
        return np.zeros(len(frame), bool)
    return frame["current_gear"].to_numpy(dtype=float) == 0


def known_wheel_force_n(frame: pd.DataFrame, vehicle, min_engine_torque_nm: float, margin_s: float,
                        brakes: bool = True) -> np.ndarray:
    """The engine's force at the wheels [N] per sample where it is known, NaN elsewhere: 0 with the
    clutch open (`clutch_open`), in gear the driveline's torque through the gear's ratio (the ratio
    the gearbox has nearest engine speed over wheel speed, as `mass.regression`); unknown within
    ``margin_s`` of a brake application or of a gear change with no neutral reported between
    (`unreported_shift`, as the mass's data filter has both; with ``brakes`` False the engine's
    force also where the brake may act, which then takes an unknown force away), while the clutch slips (the ratio no gear's), and where the torque report does
    not include the engine's drag (`knows_engine_drag`) at or below ``min_engine_torque_nm``."""
    speed = frame["speed_mps"].to_numpy(dtype=float)
    rpm = frame["engine_speed_rpm"].to_numpy(dtype=float)
    torque = driveline_torque_nm(frame)
    ratios = np.asarray(vehicle.total_ratios, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        measured = (2 * np.pi * rpm / 60.0) * vehicle.wheel_radius_m / speed
        nearest = ratios[np.argmin(np.abs(np.nan_to_num(measured, nan=-1.0)[:, None] / ratios[None, :] - 1), axis=1)]
        force = wheel_force_from_torque_n(wheel_torque_from_engine_nm(
            torque, rpm, speed, vehicle.wheel_radius_m, vehicle.driveline_efficiency), vehicle.wheel_radius_m) \
            * nearest / measured
    geared = in_gear(frame, vehicle) & ~clutch_open(frame)
    if not knows_engine_drag(frame):
        geared &= np.nan_to_num(torque, nan=-np.inf) > min_engine_torque_nm
    out = np.where(geared, force, np.nan)
    out = np.where(clutch_open(frame), 0.0, out)
    valid = frame["valid"].to_numpy(dtype=bool) if "valid" in frame.columns else np.ones(len(frame), bool)
    unknown = near((braking(frame) if brakes else False) | unreported_shift(frame), frame, margin_s)
    return np.where(unknown | ~valid, np.nan, out)


def braking(frame: pd.DataFrame) -> np.ndarray:
    """Samples with the brake switch on (J1939 SPN 597)."""
    if "brake_switch" not in frame.columns:
        return np.zeros(len(frame), bool)
    return np.nan_to_num(frame["brake_switch"].to_numpy(dtype=float)) > 0.5


def unreported_shift(frame: pd.DataFrame) -> np.ndarray:
    """Samples where the gear changed from one gear to another with no neutral reported between
    (when the clutch was open is then unknown), or where a logged gear is missing."""
    if "current_gear" not in frame.columns:
        return np.zeros(len(frame), bool)
    gear = frame["current_gear"].to_numpy(dtype=float)
    direct = np.concatenate([[False], (gear[1:] != gear[:-1]) & (gear[1:] != 0) & (gear[:-1] != 0)])
    return direct | ~np.isfinite(gear)


def near(mask: np.ndarray, frame: pd.DataFrame, margin_s: float) -> np.ndarray:
    """Samples within ``margin_s`` of a sample of ``mask``."""
    return widened(mask, int(round(margin_s / sample_step_s(frame["time_s"]))))


def windowed_force_balance(frame: pd.DataFrame, vehicle, mass_kg, moving_mps: float, min_engine_torque_nm: float,
                           margin_s: float, brakes: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample (NaN where it cannot be had): g sin(alpha) [m/s²] from the force balance integrated
    over the window of known force around it (module docstring), the window's mean acceleration
    (v_end - v_start)/T [m/s²] and the variance [m²/s⁴] of the first from the wheel speed's noise
    and the clutch's edges. Windows lie in stretches of known force above ``moving_mps``. With
    ``brakes`` False they also span the brake's applications, counting the engine's force alone:
    the brakes only take force away, so the value is then an upper bound of g sin(alpha)."""
    time_s = frame["time_s"].to_numpy(dtype=float)
    speed = frame["speed_mps"].to_numpy(dtype=float)
    mass = np.broadcast_to(np.asarray(mass_kg, dtype=float), (len(frame),))
    force = known_wheel_force_n(frame, vehicle, min_engine_torque_nm, margin_s, brakes)
    known = np.isfinite(force) & (speed > moving_mps) & np.isfinite(mass) & np.isfinite(time_s)
    excess, accel, variance = (np.full(len(frame), np.nan) for _ in range(3))
    noise = wheel_speed_noise_mps(speed, moving_mps)
    if not known.any() or not np.isfinite(noise):
        return excess, accel, variance
    dt = sample_step_s(time_s)
    width = max(MIN_SAMPLES, int(round(WINDOW_S / dt)) + 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        net = (force - aero_force_n(speed, vehicle.drag_coefficient, vehicle.frontal_area_m2)) / mass
    opened = clutch_open(frame)
    edge = np.zeros(len(frame))
    changes = np.flatnonzero(opened[1:] != opened[:-1])
    for j in changes:  # the in-gear sample beside each change: its force may belong to either side
        k = j if not opened[j] else j + 1
        edge[k] = abs(np.nan_to_num(net[k])) * dt
    for start, end in true_runs(known):
        n = end - start
        if n < MIN_SAMPLES:
            continue
        t, v, f = time_s[start:end], speed[start:end], net[start:end]
        # a force is its bin's mean, the speed the bin's first reading: v[hi] - v[lo] is the force
        # of bins lo .. hi - 1
        area = np.concatenate([[0.0], np.cumsum(f[:-1] * np.diff(t))])
        edges = np.concatenate([[0.0], np.cumsum(edge[start:end])])
        k = np.arange(n)
        size = min(width, n)
        lo = np.clip(k - size // 2, 0, n - size)
        hi = lo + size - 1
        span = t[hi] - t[lo]
        ok = span > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            mean_accel = (v[hi] - v[lo]) / span
            sine = (area[hi] - area[lo]) / span - G_MPS2 * vehicle.rolling_resistance_coefficient - mean_accel
            edge_sum = edges[hi + 1] - edges[lo]
            var = 2 * noise ** 2 / span ** 2 + (edge_sum / span) ** 2
        excess[start:end] = np.where(ok, sine, np.nan)
        accel[start:end] = np.where(ok, mean_accel, np.nan)
        variance[start:end] = np.where(ok, var, np.nan)
    return excess, accel, variance
