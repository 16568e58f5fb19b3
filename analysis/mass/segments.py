"""One mass per driving segment: the drive is cut at stops (mass changes only at standstill) and
each segment is estimated with LS (9), RLS (11)-(13) and LM (14), with an uncertainty."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics import standing
from ..road_load import G_MPS2
from ..runs import true_runs
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
    payload_stop_s: float = 10.0
    """Shorter stops than ``min_stop_s`` down to this are candidate payload changes, cut only where
    the data say the mass changed there (`split_at_payload_changes`)."""
    payload_false_alarm: float = 0.01
    """Probability of cutting a segment whose mass did not change (over all its candidate stops)."""
    min_payload_change: float = 0.03
    """Smallest relative mass change that is cut [-]."""
    gradient_bias_pct: float = 0.1
    """Systematic gradient error assumed over a segment [%-points] (the fused gradient's error
    measured on the virtual truck averages to about this over a few km); enters the uncertainty."""


def segment_bounds(time_s: np.ndarray, speed_mps: np.ndarray, settings: SegmentSettings) -> list[tuple[int, int]]:
    """[start, end) sample ranges between stops longer than ``min_stop_s``; stop samples belong
    to no segment. A gap in the speed counts as stopped only inside a stop (`kinematics.standing`)."""
    stopped = standing(time_s, speed_mps, settings.stop_speed_mps)
    long_stops = [(a, b) for a, b in true_runs(stopped) if time_s[b - 1] - time_s[a] >= settings.min_stop_s]
    bounds, start = [], 0
    for a, b in long_stops:
        if a > start:
            bounds.append((start, a))
        start = b
    if start < len(time_s):
        bounds.append((start, len(time_s)))
    return bounds


def _side_mass(phi, y, settings):
    """LS mass [kg] (9) and its standard error [kg] of the used samples: the jackknife's and that
    of a gradient bias of ``gradient_bias_pct`` (it differs between two stretches of road)."""
    used = np.isfinite(phi) & np.isfinite(y)
    if used.sum() < max(2 * settings.jackknife_blocks, settings.min_samples):
        return np.nan, np.inf
    p, q = phi[used], y[used]
    mass = float(np.sum(p * q) / np.sum(p * p))
    return mass, float(np.hypot(jackknife_uncertainty_kg(p, q, settings.jackknife_blocks),
                                gradient_bias_uncertainty_kg(mass, p, settings.gradient_bias_pct)))


def split_at_payload_changes(bounds, time_s, speed_mps, phi, y, settings: SegmentSettings):
    """``bounds`` cut further at the shorter stops (``payload_stop_s`` .. ``min_stop_s``) where the
    mass before and after differ: binary segmentation, at each step the candidate stop with the
    largest |m_before - m_after| / sqrt(s_before² + s_after²) (LS masses of the whole sides, each
    with its jackknife error and a gradient bias of its own), cut when that exceeds
    the two-sided normal quantile of ``payload_false_alarm`` shared over the candidates and the
    change is at least ``min_payload_change``. A delivery of a few seconds and a red light look the
    same in the speed; only the force balance tells them apart."""
    from scipy.stats import norm
    stopped = standing(time_s, speed_mps, settings.stop_speed_mps)
    short = [(a, b) for a, b in true_runs(stopped)
             if settings.payload_stop_s <= time_s[b - 1] - time_s[a] < settings.min_stop_s]
    out = []
    pending = list(bounds)
    while pending:
        start, end = pending.pop(0)
        inside = [(a, b) for a, b in short if start < a and b < end]
        if not inside:
            out.append((start, end))
            continue
        limit = norm.ppf(1 - settings.payload_false_alarm / (2 * len(inside)))
        best, best_score = None, limit
        for a, b in inside:
            m1, s1 = _side_mass(phi[start:a], y[start:a], settings)
            m2, s2 = _side_mass(phi[b:end], y[b:end], settings)
            if not (np.isfinite(m1) and np.isfinite(m2)) or abs(m2 / m1 - 1) < settings.min_payload_change:
                continue
            score = abs(m1 - m2) / np.hypot(s1, s2)
            if score > best_score:
                best, best_score = (a, b), score
        if best is None:
            out.append((start, end))
        else:
            pending[:0] = [(start, best[0]), (best[1], end)]
    return out


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
