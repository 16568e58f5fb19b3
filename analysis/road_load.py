"""The one vehicle model: equations (1)-(4) of ``docs/physics.md`` as array functions.

Every stage that needs a force calls these: mass estimation, load collectives, the simulator
and the virtual truck. Inputs may be scalars, NumPy arrays or pandas Series; SI units.
"""

from __future__ import annotations

import numpy as np

G_MPS2 = 9.81
"""Gravitational acceleration [m/s^2] (paper value)."""
AIR_DENSITY_KGPM3 = 1.2
"""Air density [kg/m^3], constant as in the paper."""


def road_angle_rad(gradient_pct):
    """Road angle alpha [rad] from gradient [%] = 100 tan(alpha)."""
    return np.arctan(np.asarray(gradient_pct, dtype=float) / 100.0)


def rolling_force_n(mass_kg, gradient_pct, rolling_resistance_coefficient):
    """Rolling resistance (2): F_roll = m g c_r cos(alpha) [N]."""
    return np.asarray(mass_kg) * G_MPS2 * rolling_resistance_coefficient * np.cos(road_angle_rad(gradient_pct))


def climbing_force_n(mass_kg, gradient_pct):
    """Climbing resistance (3): F_climb = m g sin(alpha) [N]."""
    return np.asarray(mass_kg) * G_MPS2 * np.sin(road_angle_rad(gradient_pct))


def aero_force_n(speed_mps, drag_coefficient, frontal_area_m2):
    """Aerodynamic drag (4): F_aero = 1/2 rho c_d A v^2 [N], no wind."""
    speed = np.asarray(speed_mps, dtype=float)
    return 0.5 * AIR_DENSITY_KGPM3 * drag_coefficient * frontal_area_m2 * speed * speed


def resistance_force_n(speed_mps, gradient_pct, mass_kg, vehicle):
    """Sum of (2)-(4) for a `analysis.vehicle.Vehicle` [N]."""
    return (rolling_force_n(mass_kg, gradient_pct, vehicle.rolling_resistance_coefficient)
            + climbing_force_n(mass_kg, gradient_pct)
            + aero_force_n(speed_mps, vehicle.drag_coefficient, vehicle.frontal_area_m2))


def wheel_force_n(speed_mps, accel_mps2, gradient_pct, mass_kg, vehicle, rotating_mass_kg=0.0):
    """Tractive force at the wheels that equation (1) requires [N]:
    F_wheel = (m + m_rot) a + F_roll + F_climb + F_aero."""
    return ((np.asarray(mass_kg) + rotating_mass_kg) * np.asarray(accel_mps2)
            + resistance_force_n(speed_mps, gradient_pct, mass_kg, vehicle))


def acceleration_mps2(wheel_force, speed_mps, gradient_pct, mass_kg, vehicle, rotating_mass_kg=0.0):
    """Equation (1) solved for a [m/s^2] given the wheel force [N]."""
    return ((np.asarray(wheel_force) - resistance_force_n(speed_mps, gradient_pct, mass_kg, vehicle))
            / (np.asarray(mass_kg) + rotating_mass_kg))


def wheel_torque_from_engine_nm(engine_torque_nm, engine_speed_rpm, speed_mps, wheel_radius_m,
                                driveline_efficiency):
    """Wheel torque from engine data [Nm]: T_wheel = eta_dl i_tot T_eng, with
    i_tot = omega_eng / omega_wheel = (2 pi n/60) r_dyn / v (NaN where v is ~0)."""
    speed = np.asarray(speed_mps, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(speed > 0.5, (2 * np.pi * np.asarray(engine_speed_rpm) / 60.0) * wheel_radius_m / speed, np.nan)
    return driveline_efficiency * ratio * np.asarray(engine_torque_nm)


def wheel_force_from_torque_n(wheel_torque_nm, wheel_radius_m):
    """F_wheel = T_wheel / r_dyn [N]."""
    return np.asarray(wheel_torque_nm) / wheel_radius_m


def wheel_speed_radps(speed_mps, wheel_radius_m):
    """Wheel angular speed [rad/s]."""
    return np.asarray(speed_mps) / wheel_radius_m
