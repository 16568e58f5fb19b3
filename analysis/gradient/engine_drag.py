"""The engine's drag on overrun from J1939 EEC3 (SPN 514), and the torque report's offset it reveals.

While the driver brakes in gear the engine is in its fuel cut: its indicated torque is zero and
a torque report net of the friction (`engine_torque.torque_report_form`) reads minus the
nominal friction, SPN 514 (`engine_friction_torque_nm`). What the report reads above that on
those samples is the report's offset: the constant part of the force balance's error, which
reaches the wheels through the gear ratio, so the smoother's single bias state cannot hold it
across the gears of an urban drive. Its median over the overrun samples is that offset. The
accessories (SPN 2978) are not in the report; in a fuel cut the wheels drive them through the
crankshaft with the friction, so the engine's drag at the wheels while it brakes is both
(`overrun_wheel_force_n`), which tightens the braking bound where the truck brakes on descents.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..engine_torque import FRICTION_COLUMN, flywheel_torque_nm, parasitic_torque_nm
from ..road_load import wheel_force_from_torque_n, wheel_torque_from_engine_nm
from ..runs import true_runs

FRICTION_MAP_UNCERTAINTY = 0.10
"""Relative 1-sigma of the engine controller's friction map (SPN 514): its friction and pumping
model against the real engine's, which move with oil temperature and wear (assumption: a
judgement of ten per cent, no source; the virtual truck's is exact but for 1 % quantisation)."""
IDLE_MARGIN = 1.1
"""Overrun only above this multiple of the idle speed: at idle the governor fuels the engine."""
RATIO_TOLERANCE = 0.04
"""Largest relative difference of engine speed / wheel speed to a gear's ratio for the clutch to
count as closed (the mass filter's)."""
MIN_SAMPLES = 50
MIN_APPLICATIONS = 3


@dataclass(frozen=True)
class TorqueOffset:
    """The torque report's offset [Nm] as the overrun samples show it, its 1-sigma [Nm], how many
    samples and brake applications it rests on."""

    offset_nm: float
    sigma_nm: float
    samples: int
    applications: int


def in_gear(frame: pd.DataFrame, vehicle) -> np.ndarray:
    """Samples whose engine speed / wheel speed is one of the gearbox's ratios (clutch closed)."""
    ratios = np.asarray(getattr(vehicle, "total_ratios", ()) or (), dtype=float)
    speed = frame["speed_mps"].to_numpy(dtype=float)
    rpm = frame["engine_speed_rpm"].to_numpy(dtype=float)
    if ratios.size == 0:
        return np.zeros(len(frame), bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        measured = (2 * np.pi * rpm / 60.0) * vehicle.wheel_radius_m / speed
        nearest = np.min(np.abs(measured[:, None] / ratios[None, :] - 1), axis=1)
    return np.nan_to_num(nearest, nan=np.inf) < RATIO_TOLERANCE


def overrun(frame: pd.DataFrame, vehicle) -> np.ndarray:
    """Samples where the engine is in its fuel cut and drags the truck: the brake on, in gear,
    above idle speed, with SPN 514 reported (and, where the log has it, no driver demand)."""
    needed = {"brake_switch", "engine_speed_rpm", "speed_mps", FRICTION_COLUMN}
    if not needed <= set(frame.columns):
        return np.zeros(len(frame), bool)
    brake = np.nan_to_num(frame["brake_switch"].to_numpy(dtype=float)) > 0.5
    rpm = frame["engine_speed_rpm"].to_numpy(dtype=float)
    idle = getattr(getattr(vehicle, "engine", None), "idle_speed_rpm", None) or 600.0
    friction = frame[FRICTION_COLUMN].to_numpy(dtype=float)
    out = brake & (np.nan_to_num(rpm) > IDLE_MARGIN * idle) & (frame["speed_mps"].to_numpy(dtype=float) > 3.0) \
        & np.isfinite(friction) & (friction > 0) & in_gear(frame, vehicle)
    if "driver_demand_torque_pct" in frame.columns:
        demand = frame["driver_demand_torque_pct"].to_numpy(dtype=float)
        out &= ~(demand > 0)
    return out


def torque_report_offset(frame: pd.DataFrame, vehicle) -> TorqueOffset | None:
    """The torque report's offset [Nm] from the overrun samples (`overrun`): the median of the
    flywheel torque plus SPN 514, which is zero in a fuel cut; its sigma from the spread of the
    brake applications' medians (samples within one application are correlated) and the friction
    map's `FRICTION_MAP_UNCERTAINTY`. None where the log has no SPN 514, fewer than `MIN_SAMPLES`
    overrun samples or `MIN_APPLICATIONS` brake applications."""
    on = overrun(frame, vehicle)
    if on.sum() < MIN_SAMPLES or "engine_torque_nm" not in frame.columns:
        return None
    residual = flywheel_torque_nm(frame) + frame[FRICTION_COLUMN].to_numpy(dtype=float)
    on &= np.isfinite(residual)
    medians = np.array([np.median(residual[start:end]) for start, end in true_runs(on)])
    if on.sum() < MIN_SAMPLES or medians.size < MIN_APPLICATIONS:
        return None
    offset = float(np.median(residual[on]))
    statistical = 1.2533 * float(np.std(medians, ddof=1)) / np.sqrt(medians.size)
    friction = float(np.median(frame[FRICTION_COLUMN].to_numpy(dtype=float)[on]))
    return TorqueOffset(offset, float(np.hypot(statistical, FRICTION_MAP_UNCERTAINTY * friction)),
                        int(on.sum()), int(medians.size))


def overrun_wheel_force_n(frame: pd.DataFrame, vehicle) -> np.ndarray:
    """The engine's drag at the wheels [N, negative] per sample where the engine is on overrun
    (`overrun`), NaN elsewhere: minus SPN 514 and the accessories' torque where the log reports it
    (SPN 2978), through the gear and the driveline's efficiency."""
    on = overrun(frame, vehicle)
    if not on.any():
        return np.full(len(frame), np.nan)
    drag = frame[FRICTION_COLUMN].to_numpy(dtype=float)
    parasitic = parasitic_torque_nm(frame)
    if parasitic is not None:
        drag = drag + parasitic
    force = wheel_force_from_torque_n(wheel_torque_from_engine_nm(
        -drag, frame["engine_speed_rpm"].to_numpy(dtype=float), frame["speed_mps"].to_numpy(dtype=float),
        vehicle.wheel_radius_m, vehicle.driveline_efficiency), vehicle.wheel_radius_m)
    return np.where(on, force, np.nan)
