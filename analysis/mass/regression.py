"""The mass regression (10) from a signals table: y = F_wheel - F_aero, phi = a + g (c_r cos a + sin a),
and the data filter of paper §2.2.2 (v > 5.5 m/s, a > 0.1 m/s², engine torque > 500 Nm, no gear
shift, no braking)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .. import road_load
from ..engine_torque import driveline_torque_nm
from ..errors import UserError
from ..kinematics import sample_step_s
from ..runs import widened


@dataclass(frozen=True)
class FilterSettings:
    """Thresholds of the data filter [SI units] and the force smoothing window [s].

    The defaults were measured on the virtual truck (``docs/estimation.md``): the paper's filter
    (`paper`, a > 0.1 m/s², T > 500 Nm) keeps only the few seconds of each acceleration and left
    regional and urban drives with no usable sample; requiring excitation of the regression itself
    (phi > 0.2 m/s², from acceleration or climbing) keeps steady uphill driving too.
    """

    min_speed_mps: float = 5.5
    min_accel_mps2: float = -0.1
    min_engine_torque_nm: float = 200.0
    min_regressor_mps2: float = 0.2
    """Lower limit of phi = a + g (c_r cos a + sin a) [m/s²] (excitation of the regression)."""
    shift_margin_s: float = 0.5
    ratio_tolerance: float = 0.04
    smoothing_window_s: float = 1.0

    @classmethod
    def paper(cls) -> "FilterSettings":
        """The filter of paper §2.2.2: v > 5.5 m/s, a > 0.1 m/s², engine torque > 500 Nm."""
        return cls(min_accel_mps2=0.1, min_engine_torque_nm=500.0, min_regressor_mps2=-np.inf, shift_margin_s=1.0)


@dataclass
class Regression:
    phi: np.ndarray
    """Regressor phi_k [m/s²] (10)."""
    y: np.ndarray
    """Output y_k = F_wheel - F_aero [N] (10)."""
    usable: np.ndarray
    """Samples passing the data filter."""
    rejected: dict[str, int]
    """How many samples each filter rule removed (a sample may fail several)."""
    force: np.ndarray | None = None
    """Wheel force F_wheel [N] (smoothed like the acceleration), every sample."""
    aero_per_cda: np.ndarray | None = None
    """1/2 rho v² [N/m²]: F_aero per m² of c_d A."""
    cos_angle: np.ndarray | None = None
    """cos(alpha) of the estimated gradient [-]."""
    excess_gradient: np.ndarray | None = None
    """a + g sin(alpha) from wheel speed and the estimated gradient [m/s²]."""
    excess_imu: np.ndarray | None = None
    """The accelerometer's a + g sin(alpha) [m/s²]: a_x,imu smoothed like the acceleration, minus
    the IMU bias (mounting pitch and accelerometer bias) the gradient smoother calibrated; None
    without an IMU or that calibration."""
    usable_imu: np.ndarray | None = None
    """The data filter where the accelerometer regressor is finite too."""
    excess_imu_std: np.ndarray | None = None
    """1-sigma of the IMU bias calibration [m/s²] (a systematic regressor error)."""
    excess_imu_shared_std: np.ndarray | None = None
    """The part of ``excess_imu_std`` the bias's error shares with the whole drive [m/s², signed]
    (``imu_bias_shared_std_mps2``); the rest is each stretch's own. None: not stated (all shared)."""
    excess_imu_ramp_std: np.ndarray | None = None
    """1-sigma of the IMU bias's drift away from the calibrated one over the drive [m/s²]
    (``imu_bias_ramp_std_mps2``: a warm-up the smoother's bias did not follow), None: not stated."""
    excess_gradient_std: np.ndarray | None = None
    """1-sigma of g sin(alpha) from the gradient's own stated sigma [m/s²] (`gradient_std_pct`),
    None where the gradient states none."""


def _centred_mean(values: np.ndarray, window: int) -> np.ndarray:
    return pd.Series(values).rolling(window, center=True, min_periods=1).mean().to_numpy()


def _column(frame, name):
    return frame[name].to_numpy(dtype=float) if name in frame.columns else None


def build_regression(frame: pd.DataFrame, vehicle, settings: FilterSettings = FilterSettings()) -> Regression:
    """Regression (10) per sample and the data filter; needs speed_mps, accel_mps2, gradient_pct,
    engine_speed_rpm, engine_torque_nm (UserError naming what is missing). The force is the
    driveline's torque (`engine_torque.driveline_torque_nm`: the accessories' torque off where the
    log reports it)."""
    needed = ["speed_mps", "accel_mps2", "gradient_pct", "engine_speed_rpm", "engine_torque_nm"]
    missing = [c for c in needed if c not in frame.columns or frame[c].isna().all()]
    if missing:
        raise UserError(f"mass: needs column(s) {', '.join(missing)} (engine data from CAN and the gradient stage)")
    time_s = frame["time_s"].to_numpy(dtype=float)
    speed, accel = _column(frame, "speed_mps"), _column(frame, "accel_mps2")
    gradient = _column(frame, "gradient_pct")
    engine_rpm, engine_torque = _column(frame, "engine_speed_rpm"), driveline_torque_nm(frame)
    dt = sample_step_s(time_s)
    window = max(1, int(round(settings.smoothing_window_s / dt)))
    margin = max(0, int(round(settings.shift_margin_s / dt)))

    wheel_torque = road_load.wheel_torque_from_engine_nm(engine_torque, engine_rpm, speed, vehicle.wheel_radius_m,
                                                         vehicle.driveline_efficiency)
    wheel_force = road_load.wheel_force_from_torque_n(wheel_torque, vehicle.wheel_radius_m)
    if vehicle.total_ratios:
        # with the clutch closed the ratio is one of the gearbox's: engine speed and wheel speed
        # come from different messages sampled at different instants, and their quotient carries
        # that timing error into the force in proportion to the acceleration (+0.5 % mass on the
        # virtual truck); samples not near any gear are dropped by the shift rule below
        ratios = np.asarray(vehicle.total_ratios)
        with np.errstate(invalid="ignore", divide="ignore"):
            measured = (2 * np.pi * engine_rpm / 60.0) * vehicle.wheel_radius_m / speed
            nearest = ratios[np.argmin(np.abs(np.nan_to_num(measured, nan=-1.0)[:, None] / ratios[None, :] - 1), axis=1)]
            wheel_force = np.where(np.isfinite(measured), wheel_force * nearest / measured, np.nan)
    # the same centred window that made accel_mps2 from wheel speed, so both sides of (1) match in time
    y = _centred_mean(wheel_force, window) - road_load.aero_force_n(speed, vehicle.drag_coefficient,
                                                                     vehicle.frontal_area_m2)
    per_kg = (road_load.rolling_force_n(1.0, gradient, vehicle.rolling_resistance_coefficient)
              + road_load.climbing_force_n(1.0, gradient))
    phi = accel + per_kg
    cos_angle = np.cos(road_load.road_angle_rad(gradient))
    rolling_per_kg = road_load.G_MPS2 * vehicle.rolling_resistance_coefficient * cos_angle
    excess_imu = None
    accel_imu, bias = _column(frame, "accel_x_mps2"), _column(frame, "imu_bias_mps2")
    if accel_imu is not None and bias is not None and np.isfinite(accel_imu).any() and np.isfinite(bias).any():
        excess_imu = _centred_mean(accel_imu, window) - bias
    bias_std = _column(frame, "imu_bias_std_mps2")
    ramp_std = _column(frame, "imu_bias_ramp_std_mps2")
    shared_std = _column(frame, "imu_bias_shared_std_mps2")

    with np.errstate(invalid="ignore", divide="ignore"):
        total_ratio = (2 * np.pi * engine_rpm / 60.0) * vehicle.wheel_radius_m / speed
    shifting = np.zeros(len(frame), bool)
    gear = _column(frame, "current_gear")
    if gear is not None:
        shifting |= np.concatenate([[False], np.diff(gear) != 0]) | ~np.isfinite(gear)
    steady = _centred_mean(total_ratio, window)
    with np.errstate(invalid="ignore", divide="ignore"):
        shifting |= ~(np.abs(total_ratio / steady - 1) < settings.ratio_tolerance)
    if vehicle.total_ratios:
        ratios = np.asarray(vehicle.total_ratios)
        with np.errstate(invalid="ignore"):
            nearest = np.min(np.abs(total_ratio[:, None] / ratios[None, :] - 1), axis=1)
        shifting |= ~(nearest < settings.ratio_tolerance)
    brake = _column(frame, "brake_switch")
    braking = np.nan_to_num(brake) > 0.5 if brake is not None else np.zeros(len(frame), bool)
    valid = frame["valid"].to_numpy(dtype=bool) if "valid" in frame.columns else np.ones(len(frame), bool)

    rules = {
        "invalid or missing data": ~valid | ~np.isfinite(y) | ~np.isfinite(phi),
        f"speed <= {settings.min_speed_mps} m/s": ~(speed > settings.min_speed_mps),
        f"acceleration <= {settings.min_accel_mps2} m/s²": ~(accel > settings.min_accel_mps2),
        f"engine torque <= {settings.min_engine_torque_nm} Nm": ~(_centred_mean(engine_torque, window)
                                                                   > settings.min_engine_torque_nm),
        "gear shift or open clutch": widened(shifting, margin + window // 2),
        "braking": widened(braking, margin + window // 2),
    }
    if np.isfinite(settings.min_regressor_mps2):
        rules[f"regressor phi <= {settings.min_regressor_mps2} m/s²"] = ~(phi > settings.min_regressor_mps2)
    usable = np.ones(len(frame), bool)
    for rejected in rules.values():
        usable &= ~rejected
    # the excitation rule is applied to the wheel-speed/gradient regressor also for the IMU one:
    # selecting samples on the noisy accelerometer itself would keep the ones its noise pushed up
    usable_imu = usable & np.isfinite(excess_imu + rolling_per_kg) if excess_imu is not None else None
    return Regression(phi=np.where(usable, phi, np.nan), y=np.where(usable, y, np.nan), usable=usable,
                      rejected={name: int(mask.sum()) for name, mask in rules.items()},
                      force=_centred_mean(wheel_force, window), aero_per_cda=0.5 * road_load.AIR_DENSITY_KGPM3 * speed ** 2,
                      cos_angle=cos_angle, excess_gradient=accel + road_load.G_MPS2 * np.sin(road_load.road_angle_rad(gradient)),
                      excess_imu=excess_imu, usable_imu=usable_imu,
                      excess_imu_std=bias_std if excess_imu is not None else None,
                      excess_imu_ramp_std=ramp_std if excess_imu is not None else None,
                      excess_imu_shared_std=shared_std if excess_imu is not None else None,
                      excess_gradient_std=gradient_regressor_std_mps2(_column(frame, "gradient_std_pct")))


def gradient_regressor_std_mps2(gradient_std_pct) -> np.ndarray | None:
    """1-sigma [m/s²] of the regressor term g sin(alpha) from the gradient's 1-sigma [%-points]:
    g · sigma/100 (d sin(atan x)/dx <= 1); None without a stated sigma."""
    if gradient_std_pct is None or not np.isfinite(gradient_std_pct).any():
        return None
    return road_load.G_MPS2 * np.asarray(gradient_std_pct, dtype=float) / 100.0
