"""The share of the wind and of the torque report's offset in the force balance that its bias
state cannot hold, as a 1-sigma per sample (`gps+can`).

A head wind w along the heading adds rho c_d A v w / m to the drag the force balance assumes
away, and a torque offset dT adds eta i dT / (r m) at the wheel: the smoother's bias state takes
a constant, not what changes with the truck's heading and speed (the wind, a fixed vector seen
along a winding road) or its gear (the offset through the ratio). For an unknown wind vector of
`WIND_PRIOR_MPS` per component the part the bias cannot hold at a sample is rho c_d A |u - mean u|
w / m with u = v h (speed times the unit heading, from the GPS track) and the mean over the
samples the force balance measures; the offset's likewise through the ratio's departure from
its mean. On the accuracy matrix the wind alone made regional `harsh` seed 3's gradient 0.60
%-pt for 0.21 without it, with 83 % of the bins inside ±2σ (100 % without). With no heading
at all (`can-only`) the wind's whole drag, gusts and its w² term included, is in the sigma
(`unknown_wind_drag_sigma_mps2`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..geodesy import local_east_north_m
from ..mass.joint import JointSettings
from ..road_load import AIR_DENSITY_KGPM3, wheel_force_from_torque_n, wheel_torque_from_engine_nm

WIND_PRIOR_MPS = JointSettings.wind_sigma_mps
"""1-sigma [m/s] of each horizontal component of the wind (the mass fit's head-wind prior): here,
in the braking bound's margin and in the given mass's road load."""
TERRAIN_ROUGHNESS_M = 0.05
"""Roughness length z0 [m] of open country with low vegetation and isolated obstacles (EN 1991-1-4
terrain category II, the code's reference terrain)."""
DRAG_HEIGHT_M = 2.0
"""Height [m] at which the wind's turbulence is taken: the middle of a truck's frontal area, also
EN 1991-1-4's lowest height z_min for terrain category II."""
TURBULENCE_INTENSITY = 1.0 / np.log(DRAG_HEIGHT_M / TERRAIN_ROUGHNESS_M)
"""The gusts' 1-sigma as a share of the mean wind speed at `DRAG_HEIGHT_M` (EN 1991-1-4 (4.7),
I_v = k_I / (c_0 ln(z / z0)) with k_I = c_0 = 1): 0.27."""
HEADING_BASE_M = 20.0
"""Distance [m] over which the heading is taken from the GPS track (its position noise is metres)."""


def head_wind_sigma_mps2(speed_mps, vehicle, mass_kg):
    """1-sigma [m/s²] of a head wind's share in the air drag per unit mass: its linear term
    rho c_d A v w / m at the `WIND_PRIOR_MPS` prior w (``speed_mps``: the speed, or here its part
    the bias cannot hold)."""
    return AIR_DENSITY_KGPM3 * vehicle.drag_coefficient * vehicle.frontal_area_m2 * speed_mps * WIND_PRIOR_MPS / mass_kg


def unknown_wind_drag_sigma_mps2(speed_mps, vehicle, mass_kg):
    """RMS [m/s²] of the drag per unit mass that a wind the log cannot see adds to the force
    balance's (which assumes still air): (rho c_d A / 2 m) ((v + w)² - v²) = (rho c_d A / 2 m)(2 v w
    + w²) with w the wind against the direction of travel. With no heading (`can-only`) w is, on
    every sample, one component a of a wind of unknown direction (the `WIND_PRIOR_MPS` prior p per
    component) plus its gusts, N(0, I² |U|²) on its own speed |U| (I the `TURBULENCE_INTENSITY`):
    E[w²] = p² (1 + 2 I²), E[w³] = 0, E[w⁴] = 3 p⁴ (1 + 8 I² + 8 I⁴), and the RMS follows from
    E[(2 v w + w²)²] = 4 v² E[w²] + E[w⁴]. The w² term, a drag whichever way the wind blows, is held
    in the RMS rather than taken off: in still air it would be an error of its own. At 20 m/s this
    is 11 % above the linear term at the prior alone, at 10 m/s 21 %, at 5 m/s 54 %."""
    p2 = WIND_PRIOR_MPS ** 2
    i2 = TURBULENCE_INTENSITY ** 2
    speed = np.asarray(speed_mps, dtype=float)
    mean_square = 4 * speed ** 2 * p2 * (1 + 2 * i2) + 3 * p2 ** 2 * (1 + 8 * i2 + 8 * i2 ** 2)
    return (AIR_DENSITY_KGPM3 * vehicle.drag_coefficient * vehicle.frontal_area_m2
            / (2 * np.asarray(mass_kg, dtype=float)) * np.sqrt(mean_square))


def heading_unit(frame: pd.DataFrame) -> np.ndarray | None:
    """Per sample the unit vector (east, north) of the direction of travel from the GPS track over
    `HEADING_BASE_M` of distance (interpolated across fixes missing in tunnels and outages; NaN
    where the truck has not moved); None without positions and distance."""
    if not {"latitude_deg", "longitude_deg", "distance_m"} <= set(frame.columns):
        return None
    lat, lon = frame["latitude_deg"].to_numpy(dtype=float), frame["longitude_deg"].to_numpy(dtype=float)
    distance = frame["distance_m"].to_numpy(dtype=float)
    fix = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(distance)
    if fix.sum() < 2:
        return None
    east, north = local_east_north_m(lat[fix], lon[fix])
    s = distance[fix]
    order = np.argsort(s, kind="stable")
    s, east, north = s[order], np.asarray(east)[order], np.asarray(north)[order]
    half = HEADING_BASE_M / 2
    de = np.interp(distance + half, s, east) - np.interp(distance - half, s, east)
    dn = np.interp(distance + half, s, north) - np.interp(distance - half, s, north)
    norm = np.hypot(de, dn)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm[:, None] > 1.0, np.column_stack([de, dn]) / norm[:, None], np.nan)


def unheld_drag_sigma_mps2(frame: pd.DataFrame, vehicle, mass_kg, virtual, offset_sigma_nm: float) -> np.ndarray:
    """1-sigma [m/s²] per sample of the wind's and the torque offset's share in the force balance
    that a constant bias does not hold (module docstring), NaN where ``virtual`` does not measure.
    ``offset_sigma_nm``: the torque report offset's 1-sigma [Nm]."""
    measured = np.isfinite(np.asarray(virtual, dtype=float))
    out = np.full(len(frame), np.nan)
    if not measured.any():
        return out
    mass = np.broadcast_to(np.asarray(mass_kg, dtype=float), (len(frame),))
    speed = frame["speed_mps"].to_numpy(dtype=float)
    variance = np.zeros(len(frame))
    heading = heading_unit(frame)
    if heading is not None:
        u = speed[:, None] * heading
        ok = measured & np.all(np.isfinite(u), axis=1)
        if ok.any():
            spread = np.linalg.norm(u - u[ok].mean(axis=0), axis=1)
            variance += np.nan_to_num(head_wind_sigma_mps2(spread, vehicle, mass)) ** 2
    if "engine_speed_rpm" in frame and np.isfinite(offset_sigma_nm):
        with np.errstate(invalid="ignore", divide="ignore"):
            per_nm = wheel_force_from_torque_n(wheel_torque_from_engine_nm(
                1.0, frame["engine_speed_rpm"].to_numpy(dtype=float), speed, vehicle.wheel_radius_m,
                vehicle.driveline_efficiency), vehicle.wheel_radius_m) / mass
        ok = measured & np.isfinite(per_nm)
        if ok.any():
            variance[ok] += ((per_nm[ok] - per_nm[ok].mean()) * offset_sigma_nm) ** 2
    out[measured] = np.sqrt(variance[measured])
    return out
