"""One mass per driving segment: the drive is cut at stops (mass changes only at standstill) and
each segment is estimated with LS (9), RLS (11)-(13) and LM (14), with an uncertainty."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..road_load import G_MPS2
from . import kernels


@dataclass(frozen=True)
class SegmentSettings:
    """Segmentation, estimator parameters and the 'do we know' limits."""

    stop_speed_mps: float = 0.5
    min_stop_s: float = 60.0
    forgetting_factor: float = 0.9985
    """lambda of (11)-(13) and (14); the paper's test drive value."""
    initial_covariance: float = 1000.0
    """P_0 of the RLS [kg² s⁴/m²... per (m/s²)²]: large, so theta_0 is forgotten within seconds."""
    damping: float = 0.1
    """mu of (14) [s⁴/m²]; about 2 samples' worth of phi² at a = 0.3 m/s²."""
    min_samples: int = 150
    jackknife_blocks: int = 10
    max_relative_uncertainty: float = 0.05
    gradient_bias_pct: float = 0.1
    """Systematic gradient error assumed over a segment [%-points] (the fused gradient's error
    measured on the virtual truck averages to about this over a few km); enters the uncertainty."""


def segment_bounds(time_s: np.ndarray, speed_mps: np.ndarray, settings: SegmentSettings) -> list[tuple[int, int]]:
    """[start, end) sample ranges between stops longer than ``min_stop_s``; stop samples belong
    to no segment. NaN speed counts as not stopped (a gap is not evidence of a load change)."""
    stopped = np.nan_to_num(speed_mps, nan=np.inf) < settings.stop_speed_mps
    edges = np.flatnonzero(np.diff(np.concatenate([[0], stopped.astype(np.int8), [0]])))
    long_stops = [(a, b) for a, b in zip(edges[::2], edges[1::2]) if time_s[b - 1] - time_s[a] >= settings.min_stop_s]
    bounds, start = [], 0
    for a, b in long_stops:
        if a > start:
            bounds.append((start, a))
        start = b
    if start < len(time_s):
        bounds.append((start, len(time_s)))
    return bounds


def jackknife_uncertainty_kg(phi: np.ndarray, y: np.ndarray, blocks: int) -> float:
    """Standard error [kg] of the LS mass (9) by a delete-one-block jackknife over contiguous blocks
    of the used samples: honest under the strong autocorrelation of 10 Hz residuals and under
    gradient errors that vary along the road."""
    n = len(phi)
    if n < 2 * blocks:
        return np.inf
    edges = np.linspace(0, n, blocks + 1).astype(int)
    sxy, sxx = np.add.reduceat(phi * y, edges[:-1]), np.add.reduceat(phi * phi, edges[:-1])
    leave_out = (sxy.sum() - sxy) / (sxx.sum() - sxx)
    return float(np.sqrt((blocks - 1) / blocks * np.sum((leave_out - leave_out.mean()) ** 2)))


def gradient_bias_uncertainty_kg(mass_kg: float, phi: np.ndarray, gradient_bias_pct: float) -> float:
    """Mass error [kg] of (9) when every phi_k carries the same error g * sin(bias):
    dm = m g dsin(alpha) sum(phi) / sum(phi^2)."""
    return float(abs(mass_kg) * G_MPS2 * np.sin(np.arctan(gradient_bias_pct / 100)) * np.sum(phi) / np.sum(phi * phi))


def estimate_segment(phi: np.ndarray, y: np.ndarray, curb_mass_kg: float, max_mass_kg: float,
                     settings: SegmentSettings) -> dict:
    """Masses [kg] of one segment by all three methods, the LS uncertainty [kg], a status
    ('ok', 'uncertain', 'no_excitation', 'implausible') and the reason; plus the RLS and LM
    trajectories per sample (held where a sample is not used)."""
    used = np.isfinite(phi) & np.isfinite(y)
    n = int(used.sum())
    phi2 = phi.reshape(-1, 1)
    rls_path = kernels.rls(phi2, y, settings.forgetting_factor, np.array([curb_mass_kg]),
                           np.array([[settings.initial_covariance]]))[:, 0]
    lm_path = kernels.levenberg_marquardt(phi2, y, settings.forgetting_factor, settings.damping,
                                          np.array([curb_mass_kg]))[:, 0]
    result = {"n_samples": n, "mass_ls_kg": None, "mass_rls_kg": None, "mass_lm_kg": None,
              "uncertainty_kg": None, "rls_path": rls_path, "lm_path": lm_path}
    if n < settings.min_samples:
        return {**result, "status": "no_excitation",
                "reason": f"only {n} samples pass the data filter (need {settings.min_samples})"}
    mass = float(kernels.least_squares(phi2, y)[0])
    statistical = jackknife_uncertainty_kg(phi[used], y[used], settings.jackknife_blocks)
    uncertainty = float(np.hypot(statistical, gradient_bias_uncertainty_kg(mass, phi[used], settings.gradient_bias_pct)))
    result.update(mass_ls_kg=mass, mass_rls_kg=float(rls_path[-1]), mass_lm_kg=float(lm_path[-1]),
                  uncertainty_kg=uncertainty)
    if not (0.5 * curb_mass_kg < mass < max_mass_kg):
        return {**result, "status": "implausible",
                "reason": f"LS mass {mass:.0f} kg outside {0.5 * curb_mass_kg:.0f}..{max_mass_kg:.0f} kg "
                          f"(check the vehicle file and the engine torque scaling)"}
    if not np.isfinite(uncertainty):
        return {**result, "uncertainty_kg": None, "status": "uncertain",
                "reason": f"too few samples ({n}) for an uncertainty"}
    if uncertainty > settings.max_relative_uncertainty * mass:
        return {**result, "status": "uncertain",
                "reason": f"uncertainty {uncertainty:.0f} kg is over {100 * settings.max_relative_uncertainty:.0f} % "
                          f"(too little excitation: {n} samples)"}
    return {**result, "status": "ok", "reason": ""}
