"""c_r and c_d·A shared by every log of one truck, a mass per segment of every log, and the
torque-gain calibration from one weighing, from additive per-log moments.

The joint fit of one drive (`analysis.mass.joint`) solves, per used sample k of segment j,

    F_k = m_j (ψ_k + c_r g cos α_k) + c_d A q_k        (instrument z_k for ψ_k)

by robust, instrumental-variable Gauss-Newton. With the robust weights w_k of the log's own fit
held fixed, everything the fit needs of a segment is the weighted cross-product matrix
Σ w u uᵀ of u = (z, ψ, g cos α, q, F): the normal equations, the residual sum and, kept per
30 s residual block, the block-robust (sandwich) covariance. These 5×5 blocks add across logs,
so the map step returns them (`SegmentMoments`, picklable) and the reduce step solves the truck.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import UserError
from ..mass import calibration
from ..mass.joint import COEFFICIENTS, JointSettings
from ..road_load import G_MPS2

U_FIELDS = ("instrument", "regressor", "g_cos_angle", "aero_per_cda", "force")


@dataclass
class SegmentMoments:
    """One mass segment of one log: Σ w u uᵀ per residual block (``blocks``, shape (n, 5, 5)),
    u = (z, ψ, g cos α, ½ρv², F_wheel) in SI units, with the log's robust weights."""

    log: str
    segment: int
    """Number within its log, from 1 (as printed and as ``--known-mass`` counts)."""
    start_s: float
    end_s: float
    samples: int
    regressor: str
    blocks: np.ndarray
    bias_fraction: float = 0.0
    """The log's systematic regressor-bias 1-sigma of this segment's mass, relative to the mass."""
    slope_share: float = 1.0
    """The log's robust fit's mean weight slope over its mean weight on this segment (`JointFit.slope_share`):
    the factor on its moments in the covariance's normal matrix."""


def segment_moments(log: str, mass_result, time_s, settings: JointSettings = JointSettings()) -> list[SegmentMoments]:
    """The `SegmentMoments` of every segment the log's joint fit used (`analysis.mass.MassResult`)."""
    fit = mass_result.joint
    if fit is None:
        return []
    regression = mass_result.regression
    use_imu = fit.regressor == "imu"
    excess = regression.excess_imu if use_imu else regression.excess_gradient
    instrument = regression.excess_gradient if use_imu else excess
    u_all = np.column_stack([instrument, excess, G_MPS2 * regression.cos_angle, regression.aero_per_cda,
                             regression.force])
    time_s = np.asarray(time_s, float)
    out = []
    for j, segment in enumerate(mass_result.segments):
        start = int(np.searchsorted(time_s, segment["start_s"], side="left"))
        end = int(np.searchsorted(time_s, segment["end_s"], side="right"))
        w = fit.weights[start:end]
        used = (w > 0) & np.isfinite(u_all[start:end]).all(axis=1)
        if not np.isfinite(fit.masses_kg[j]) or used.sum() < settings.min_samples:
            continue
        u, w, t = u_all[start:end][used], w[used], time_s[start:end][used]
        block = np.floor((t - t[0]) / settings.block_s).astype(np.int64)
        _, block = np.unique(block, return_inverse=True)
        blocks = np.zeros((int(block.max()) + 1, 5, 5))
        np.add.at(blocks, block, (w[:, None, None] * u[:, :, None] * u[:, None, :]))
        bias = float(fit.sensitivity_kg[j] / fit.masses_kg[j]) if fit.masses_kg[j] else 0.0
        share = float(fit.slope_share[j]) if fit.slope_share is not None and np.isfinite(fit.slope_share[j]) else 1.0
        out.append(SegmentMoments(log, j + 1, float(segment["start_s"]), float(segment["end_s"]), int(used.sum()),
                                  fit.regressor, blocks, bias, share))
    return out


def _linearised(theta, totals, n_seg):
    """Normal matrix and right-hand side of the Gauss-Newton step from the segments' Σ w u uᵀ."""
    n_p = n_seg + 2
    normal, rhs = np.zeros((n_p, n_p)), np.zeros(n_p)
    c_r, cda = theta[n_seg], theta[n_seg + 1]
    for j in range(n_seg):
        rows, residual = _rows(theta[j], c_r, cda)
        index = [j, n_seg, n_seg + 1]
        columns = np.array([[0, 1, c_r, 0, 0], rows[1], rows[2]])
        normal[np.ix_(index, index)] += rows @ totals[j] @ columns.T
        rhs[index] += rows @ totals[j] @ residual
    return normal, rhs


def _rows(mass, c_r, cda):
    """Instrument rows (for m_j, c_r, c_d·A) and the residual r = F − m(ψ + c_r g cos) − c_d A q,
    each as coefficients on u."""
    rows = np.array([[1.0, 0, c_r, 0, 0], [0, 0, mass, 0, 0], [0, 0, 0, 1.0, 0]])
    return rows, np.array([0.0, -mass, -mass * c_r, -cda, 1.0])


def _solve(theta, totals, n_seg, settings, prior=None):
    theta = theta.copy()
    normal = np.eye(n_seg + 2)
    for _ in range(settings.iterations):
        normal, rhs = _linearised(theta, totals, n_seg)
        if prior is not None:
            centre, precision = prior
            normal = normal + np.diag(precision)
            rhs = rhs + precision * (centre - theta)
        step = np.linalg.solve(normal, rhs)
        theta += step
        if np.max(np.abs(step) / np.maximum(np.abs(theta), 1e-9)) < settings.tolerance:
            break
    return theta, normal


def _covariance(theta, normal, parts, n_seg, extra_meat=None):
    """Block-robust sandwich N⁻¹ (Σ_b s_b s_bᵀ) N⁻ᵀ, s_b the score of residual block b."""
    scores = []
    for j, part in enumerate(parts):
        rows, residual = _rows(theta[j], theta[n_seg], theta[n_seg + 1])
        s = np.einsum("ra,bac,c->br", rows, part.blocks, residual)
        full = np.zeros((len(s), n_seg + 2))
        full[:, j], full[:, n_seg], full[:, n_seg + 1] = s[:, 0], s[:, 1], s[:, 2]
        scores.append(full)
    scores = np.concatenate(scores)
    n_blocks, p = len(scores), n_seg + 2
    meat = scores.T @ scores * n_blocks / max(n_blocks - p, 1)
    if extra_meat is not None:
        meat = meat + extra_meat
    inverse = np.linalg.inv(normal)
    return inverse @ meat @ inverse.T


def fit_truck(parts: list[SegmentMoments], vehicle, known: dict[tuple[str, int], float] | None = None,
              settings: JointSettings = JointSettings()) -> dict:
    """The truck's shared c_r and c_d·A (value, std, identified, reason), its torque gain and every
    segment's mass with its total 1-sigma, from the `SegmentMoments` of all its logs (in path
    order). ``known`` {(log, segment number): kg}: weighed segments calibrating the torque gain."""
    known = known or {}
    datasheet = {"rolling_resistance_coefficient": vehicle.rolling_resistance_coefficient,
                 "drag_area_m2": vehicle.drag_coefficient * vehicle.frontal_area_m2}
    if not parts:
        if known:
            raise UserError("known_masses: no segment of this truck has a joint mass fit to calibrate against")
        return {"logs": 0, "segments": [], "notes": ["no segment with enough samples for the joint fit"],
                **{name: {"value": value, "std": None, "identified": False,
                          "reason": "no segment with enough samples"} for name, value in datasheet.items()}}
    n_seg = len(parts)
    totals = np.array([part.blocks.sum(axis=0) for part in parts])
    c_r0, cda0 = datasheet["rolling_resistance_coefficient"], datasheet["drag_area_m2"]
    psi = totals[:, 1, :] + c_r0 * totals[:, 2, :]
    theta0 = np.concatenate([(psi[:, 4] - cda0 * psi[:, 3]) / (psi[:, 1] + c_r0 * psi[:, 2]), [c_r0, cda0]])
    prior_std = np.array([settings.rolling_resistance_uncertainty * c_r0, settings.drag_area_uncertainty * cda0])
    try:
        theta, normal = _solve(theta0, totals, n_seg, settings)
        sandwich = _covariance(theta, normal, parts, n_seg)
        noise_var = float(np.median(np.diag(sandwich)[:n_seg] / np.abs(np.diag(np.linalg.inv(normal))[:n_seg])))
    except np.linalg.LinAlgError:
        noise_var = float(np.median(totals[:, 4, 4] / np.maximum(totals[:, 0, 0], 1e-12)))
    precision = np.concatenate([np.zeros(n_seg), noise_var / prior_std ** 2])
    index = {(part.log, part.segment): j for j, part in enumerate(parts)}
    missing = [f"{log} segment {number}" for log, number in known if (log, number) not in index]
    if missing:
        raise UserError(f"known_masses: {', '.join(missing)} has no joint mass fit to calibrate against (segments "
                        f"with one: {', '.join(f'{p.log} {p.segment}' for p in parts[:6])}"
                        f"{', …' if n_seg > 6 else ''})")
    weighed = {index[key]: kg for key, kg in known.items()}
    gain_uncertainty = float(np.hypot(settings.torque_gain_uncertainty, settings.driveline_efficiency_uncertainty))
    gain_value = 1.0
    # the fit sees k·c_d·A (F_aero is scaled by the torque gain k like every force): once a
    # weighing gives k, the datasheet's c_d·A is a prior on c_d·A·k, and the fit is repeated
    for _ in range(3 if weighed else 1):
        centre = theta0.copy()
        centre[n_seg + 1] = cda0 * gain_value
        theta, normal = _solve(theta0, totals, n_seg, settings, prior=(centre, precision))
        shares = np.array([part.slope_share for part in parts])
        bread = _linearised(theta, totals * shares[:, None, None], n_seg)[0] + np.diag(precision)
        cov = _covariance(theta, bread, parts, n_seg, extra_meat=noise_var * np.diag(precision))
        std = np.sqrt(np.abs(np.diag(cov)))
        masses, mass_std = theta[:n_seg], std[:n_seg]
        bias = np.array([part.bias_fraction for part in parts]) * np.abs(masses)
        # each part's systematic term (its log's auxiliary power and regressor bias, one number)
        # taken as its own: the pooled fit's covariance holds what the logs share
        covariance = cov[:n_seg, :n_seg] + np.diag(bias ** 2)
        corrected, total, gain = calibration.calibrate(masses, mass_std, bias, weighed, gain_uncertainty, covariance)
        gain_value = gain["gain"]
    if gain["calibrated_from"] is not None:
        gain["calibrated_from"] = [{"log": parts[j - 1].log, "segment": parts[j - 1].segment}
                                   for j in gain["calibrated_from"]]
    result = {"logs": len({part.log for part in parts}), "torque_gain": gain,
              "condition_number": float(np.linalg.cond(normal / np.sqrt(np.outer(np.diag(normal), np.diag(normal))))),
              "notes": []}
    for k, name in enumerate(COEFFICIENTS):
        value, sigma = float(theta[n_seg + k]), float(std[n_seg + k])
        relative = sigma / abs(value) if value else np.inf
        identified = sigma <= settings.max_prior_fraction * prior_std[k] * (gain_value if k else 1.0) and relative <= settings.max_relative_std
        reason = "identified" if identified else (
            f"not identifiable on this truck's logs (std {100 * relative:.1f} %, {100 * sigma / prior_std[k]:.0f} % "
            f"of the datasheet's): stays near the vehicle file")
        scale = 1 / gain["gain"] if name == "drag_area_m2" else 1.0  # F_aero scales with the torque gain
        result[name] = {"value": value * scale, "std": sigma * scale, "identified": bool(identified),
                        "reason": reason}
        if not identified:
            result["notes"].append(f"{name}: {reason}")
    result["segments"] = [{"log": part.log, "segment": part.segment, "start_s": part.start_s, "end_s": part.end_s,
                           "samples": part.samples, "regressor": part.regressor,
                           "mass_kg": float(corrected[j]), "mass_uncertainty_kg": float(total[j])}
                          for j, part in enumerate(parts)]
    return result
