"""Joint mass and road load over one drive: a mass per segment plus the rolling-resistance
coefficient c_r and the drag area c_d·A shared by all segments, by robust Gauss-Newton least
squares over the stacked segments, with a block-robust covariance.

Per used sample k of segment j (F_wheel from engine torque, ψ = a + g sin α from the IMU or from
wheel speed and the estimated gradient):

    F_wheel,k = m_j (ψ_k + g c_r cos α_k) + c_d A · ½ ρ v_k²

A torque-report (or driveline-efficiency) gain error k scales F_wheel: it turns every mass into
k·m and c_d A into k·c_d A and cannot be seen within the data. Without a known mass it is part of
each mass's uncertainty; one weighed segment calibrates it for all others.

Optional columns: the drive's wind, an offset of the torque report (both shared) and an auxiliary
power P_j per segment, the engine power the compressor, fan and alternator take before the
driveline: P_j η / v at the wheel, P_j >= 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from ..kinematics import distance_m
from ..road_load import AIR_DENSITY_KGPM3, G_MPS2
from .gusts import gust_covariance, gust_meat

COEFFICIENTS = ("rolling_resistance_coefficient", "drag_area_m2")


@dataclass(frozen=True)
class JointSettings:
    """Robust weighting, covariance blocks, identifiability and the gain uncertainty."""

    robust_tuning: float = 4.685
    """Tukey biweight constant in robust sigmas (95 % efficiency under Gaussian noise): samples
    where an unmodelled force (air compressor, fan, PTO, unflagged braking) breaks the balance
    get weight 0."""
    iterations: int = 40
    tolerance: float = 1e-7
    """Largest relative parameter step at which the iteration stops (1e-7 of a mass is a gram)."""
    block_s: float = 30.0
    """Length of the residual blocks of the covariance [s]: residuals of 10 Hz data are
    correlated over seconds (smoothing, gusts, gradient error), not over blocks."""
    max_relative_std: float = 0.25
    """c_r or c_d·A counts as identified when its relative standard deviation is below this ..."""
    max_prior_fraction: float = 0.5
    """... and the drive has at least halved the datasheet's standard deviation."""
    torque_gain_uncertainty: float = 0.03
    """Relative 1-sigma of the engine's actual-torque report (J1939 SPN 513: a few % of reference)."""
    driveline_efficiency_uncertainty: float = 0.02
    rolling_resistance_uncertainty: float = 0.15
    """Relative 1-sigma of a datasheet c_r, used when the drive cannot identify it."""
    drag_area_uncertainty: float = 0.10
    torque_offset_uncertainty: float = 0.02
    """Prior 1-sigma of the torque report's offset [fraction of the reference torque]."""
    fit_torque_offset: bool = True
    """Fit a constant offset of the engine torque report with the masses."""
    fit_wind: bool = True
    """Fit the drive's wind (east, north) with the masses where the log has GPS positions."""
    wind_sigma_mps: float = 5.0
    """Prior 1-sigma of each horizontal wind component [m/s] (a fresh breeze at truck height)."""
    max_relative_uncertainty: float = 0.05
    max_rejected_share: float = 1 / 3
    """A segment where the robust fit rejects more than this share of the samples has a force
    balance the model does not hold (an auxiliary load running most of the time, a PTO, unflagged
    braking): its mass is "not confident" (measured: 65 % rejected on a segment 37 % off)."""
    min_samples: int = 150
    gust_intensity: float = 0.37
    """Turbulence intensity sigma_u / U of the wind at a truck's height, 1 / ln(z / z0) of the
    neutral surface layer with z = 3 m and z0 = 0.2 m (farmland with hedges, scattered buildings):
    the gusts' share of the masses' covariance between blocks (`gusts`). 0: left out."""
    gust_length_m: float = 150.0
    """Distance of travel over which the head wind's gusts stay correlated [m] (the virtual truck's;
    the drive's residual cannot measure it, real logs have yet to confirm it)."""
    aux_power_sigma_w: float = 5000.0
    """Prior 1-sigma of each segment's auxiliary power [W] (half-normal, P >= 0): the average engine
    power a truck's compressor, cooling fan, alternator and steering pump take while driving is a
    few kW (the vehicle files' ``auxiliary_power_w`` for the same consumers: 4-6 kW). 0: not fitted."""
    parasitic_estimate_uncertainty: float = 0.15
    """Relative 1-sigma of the engine's own estimate of its accessories' torque (J1939 EEC3, SPN
    2978): an engine controller takes it from maps of its fan and compressor (fan power as the fan
    law's N³ at the bench's air density, which moves by ±10 % between -10 and +30 °C and by -10 % at
    1000 m; a compressor's with the system pressure it pumps against). Where the log's SPN 2978 is
    taken off the force, a power the drive cannot resolve holds this share of it, not the whole
    accessories' ``aux_power_sigma_w`` (`fit_joint`'s ``aux_prior_w``)."""


@dataclass
class JointFit:
    masses_kg: np.ndarray
    """One per segment (NaN where the segment had too few samples)."""
    mass_std_kg: np.ndarray
    """Statistical 1-sigma (block-robust), without gain or fixed-coefficient terms."""
    coefficients: dict[str, float]
    coefficient_std: dict[str, float | None]
    identified: dict[str, bool]
    reasons: dict[str, str]
    sensitivity_kg: np.ndarray
    """Further systematic 1-sigma per segment [kg]: an auxiliary power's prior where the drive cannot
    resolve it (the coefficients' uncertainty is in the covariance)."""
    weights: np.ndarray
    """Robust weight of every sample (0 for samples not used)."""
    regressor_values: np.ndarray
    """The mass regressor psi + g c_r cos(alpha) of every sample [m/s²] (0 for samples not used)."""
    samples: np.ndarray
    outliers: int
    regressor: str = ""
    rejected_share: np.ndarray | None = None
    """Per segment, the share of its used samples the robust fit gave weight 0 (NaN: not fitted)."""
    condition: float = np.nan
    notes: list[str] = field(default_factory=list)
    aux_power_w: np.ndarray | None = None
    """Per segment, the auxiliary power the fit found [W] (None: not fitted; NaN: segment not fitted)."""
    aux_power_std_w: np.ndarray | None = None
    aux_identified: np.ndarray | None = None
    """Per segment, whether the drive at least halved the auxiliary power's prior width."""
    slope_share: np.ndarray | None = None
    """Per segment, the robust weights' mean slope over their mean (`_biweight_slope_share`), which
    the covariance's normal matrix carries (NaN: not fitted)."""
    headless_samples: np.ndarray | None = None
    """Per segment, the used samples without a GPS heading, fitted with their head wind in the
    covariance (`_headless_wind_covariance`); None: not fitted."""
    regressor_response: np.ndarray | None = None
    """(samples, segments) how each segment's mass moves per unit error of the mass regressor at
    each sample [kg per m/s²], through the whole fit (`_regressor_response`); 0 for samples not used."""
    mass_covariance_kg2: np.ndarray | None = None
    """The masses' statistical covariance [kg²] (segments x segments; its diagonal is
    ``mass_std_kg``²): the shared parameters' share (c_r, c_d·A, wind, torque offset, gusts) moves
    all masses together, which a weighing corrects for the other segments (`calibration`). NaN
    rows and columns for a segment without a mass."""


@numba.njit(cache=True)
def _residual(force, excess, cos_angle, aero, extra, aux, seg, theta, n_seg):
    """F - m_j (psi + g c_r cos) - c_d A q - sum_e p_e extra_e - P_j aux per sample [N] (the
    auxiliary powers P_j, one per segment, follow the shared extras in theta when it has them)."""
    c_r, cda = theta[n_seg], theta[n_seg + 1]
    n_extra = extra.shape[1]
    has_aux = len(theta) > n_seg + 2 + n_extra
    out = np.empty(len(force))
    for k in range(len(force)):
        value = force[k] - theta[seg[k]] * (excess[k] + G_MPS2 * c_r * cos_angle[k]) - cda * aero[k]
        for e in range(n_extra):
            value -= theta[n_seg + 2 + e] * extra[k, e]
        if has_aux:
            value -= theta[n_seg + 2 + n_extra + seg[k]] * aux[k]
        out[k] = value
    return out


@numba.njit(cache=True)
def _biweight(residual, limit):
    """Tukey biweight (1 - (r/limit)²)² inside the limit, 0 outside."""
    out = np.empty(len(residual))
    for k in range(len(residual)):
        u = residual[k] / limit
        out[k] = (1 - u * u) ** 2 if abs(u) < 1 else 0.0
    return out


@numba.njit(cache=True)
def _normal_equations(excess, instrument, cos_angle, aero, extra, aux, seg, theta, n_seg, weights, residual):
    """Gauss-Newton normal matrix sum w z_k j_k^T (instrument rows z, Jacobian columns j) and
    right-hand side sum w z_k r_k over all samples, parameters (m_1..m_J, c_r, c_d A, p_1..p_E
    and, where theta has them, P_1..P_J)."""
    n_extra = extra.shape[1]
    n_p = len(theta)
    n_local = 4 if n_p > n_seg + 2 + n_extra else 3
    full = np.zeros((n_p, n_p))
    rhs = np.zeros(n_p)
    c_r = theta[n_seg]
    column = np.empty(n_local + n_extra)
    row = np.empty(n_local + n_extra)
    index = np.empty(n_local + n_extra, dtype=np.int64)
    for e in range(n_extra):
        index[n_local + e] = n_seg + 2 + e
    for k in range(len(excess)):
        w = weights[k]
        if w == 0.0:
            continue
        j = seg[k]
        rolling = G_MPS2 * c_r * cos_angle[k]
        column[0], column[1], column[2] = excess[k] + rolling, theta[j] * G_MPS2 * cos_angle[k], aero[k]
        row[0], row[1], row[2] = instrument[k] + rolling, column[1], column[2]
        index[0], index[1], index[2] = j, n_seg, n_seg + 1
        if n_local == 4:
            column[3], row[3], index[3] = aux[k], aux[k], n_seg + 2 + n_extra + j
        for e in range(n_extra):
            column[n_local + e] = extra[k, e]
            row[n_local + e] = extra[k, e]
        for a in range(n_local + n_extra):
            wa = w * row[a]
            rhs[index[a]] += wa * residual[k]
            for b in range(n_local + n_extra):
                full[index[a], index[b]] += wa * column[b]
    return full, rhs


def _solve(force, excess, cos_angle, aero, extra, aux, seg, n_seg, theta, free, settings, weights=None, prior=None,
           instrument=None, floor=1e-9):
    """Robust Gauss-Newton (iteratively reweighted, Tukey biweight on the residual scale); with
    ``weights`` given they stay fixed. With an ``instrument`` for ``excess`` (a regressor whose
    errors are independent of its noise) the normal equations are the instrumental-variable ones
    Z^T W r = 0, so the noise of ``excess`` does not bias the masses low. The iteration stops when
    no free parameter moves by more than ``tolerance`` of max(|value|, ``floor``). Returns theta,
    weights, the normal matrix of the free parameters, residuals, the mass regressor and its instrument."""
    theta = theta.copy()
    fixed_weights = weights is not None
    weights = np.ones(len(force)) if weights is None else weights
    instrument = excess if instrument is None else instrument
    free_idx = np.flatnonzero(free)
    normal = np.eye(len(free_idx))
    step, kept, halvings = None, None, 0
    for _ in range(settings.iterations):
        residual = _residual(force, excess, cos_angle, aero, extra, aux, seg, theta, n_seg)
        if not fixed_weights:
            sample = residual[::max(1, len(residual) // 50_000)]  # a robust scale needs no more
            scale = 1.4826 * np.median(np.abs(sample - np.median(sample)))
            new_weights = _biweight(residual, settings.robust_tuning * max(scale, 1e-9))
            new_kept = np.count_nonzero(new_weights)
            if step is not None and new_kept < 0.5 * kept and halvings < 10:
                # the step overshot to a fit that explains few of the samples the last one did
                # (a near-singular instrumental system): go half of it back and look again
                step = 0.5 * step
                theta[free_idx] -= step
                halvings += 1
                continue
            weights, kept = new_weights, new_kept
        full, rhs = _normal_equations(excess, instrument, cos_angle, aero, extra, aux, seg, theta, n_seg, weights,
                                      residual)
        if prior is not None:
            centre, precision = prior
            full += np.diag(precision)
            rhs += precision * (centre - theta)
        normal = full[np.ix_(free_idx, free_idx)]
        try:
            step = np.linalg.solve(normal, rhs[free_idx])
        except np.linalg.LinAlgError:  # a parameter the weighted data no longer see: left where it is
            step = np.linalg.lstsq(normal, rhs[free_idx], rcond=None)[0]
        theta[free_idx] += step
        if np.max(np.abs(step) / np.maximum(np.abs(theta[free_idx]), np.broadcast_to(floor, theta.shape)[free_idx])) \
                < settings.tolerance:
            break
    c_r = theta[n_seg]
    residual = _residual(force, excess, cos_angle, aero, extra, aux, seg, theta, n_seg)
    return theta, weights, normal, residual, excess + G_MPS2 * c_r * cos_angle, instrument + G_MPS2 * c_r * cos_angle


def _regressor_response(plain, score_rows, theta, seg, n_seg, precision, moving):
    """Per used sample k, how each segment's mass moves per unit error of the mass regressor there
    [kg per m/s²] (n_used, segments): an error δφ_k changes the residual by -m_j δφ_k, and the
    converged fit's estimating equations Σ w z r = 0 (with the priors) answer with
    δθ = -N⁻¹ w_k z_k m_j δφ_k over the parameters that move (``moving``: not held, not at a
    bound), so c_r, c_d·A, the wind and the offset carry a regressor error from one segment to
    every other. ``plain``: the fit's normal matrix without its priors, ``score_rows`` its samples'
    w_k z_k (`_score_rows`)."""
    normal = (plain + np.diag(precision))[np.ix_(moving, moving)]
    masses = np.linalg.lstsq(normal, np.eye(len(normal))[:, :n_seg], rcond=None)[0]  # N⁻¹'s mass columns
    return -(score_rows[:, moving] @ masses) * theta[:n_seg][seg][:, None]


def _informed_inverse(normal: np.ndarray) -> np.ndarray:
    """Inverse of the normal matrix over the parameters the weighted data still see; NaN rows and
    columns for one they no longer see (every sample of a segment weighted out as an outlier), so
    that parameter has no uncertainty to state instead of making the whole system singular."""
    informed = np.diag(normal) > 0
    inverse = np.full(normal.shape, np.nan)
    inverse[np.ix_(informed, informed)] = np.linalg.inv(normal[np.ix_(informed, informed)])
    return inverse


def _score_rows(n_seg, seg, weights, instrument_row, theta, cos_angle, aero, extra, aux):
    """Each sample's score row, weight times instrument row (the score is the row times the
    residual) [n x parameters]."""
    n_p = len(theta)
    rows = np.zeros((len(seg), n_p))
    index = np.arange(len(seg))
    rows[index, seg] = weights * instrument_row
    rows[:, n_seg] = weights * theta[:n_seg][seg] * G_MPS2 * cos_angle
    rows[:, n_seg + 1] = weights * aero
    for e in range(extra.shape[1]):
        rows[:, n_seg + 2 + e] = weights * extra[:, e]
    if n_p > n_seg + 2 + extra.shape[1]:
        rows[index, n_seg + 2 + extra.shape[1] + seg] = weights * aux
    return rows


def _block_covariance(normal, free_idx, n_seg, seg, block, weights, residual, instrument_row, theta, cos_angle,
                      aero, extra, aux, extra_meat=None, gusts=None):
    """Sandwich covariance N^-1 (sum_b s_b s_b^T) N^-T with s_b the score (instrument rows times
    residual) of residual block b: honest under correlation within blocks. ``gusts`` (speed, distance,
    `gusts.GustCovariance`, the normal matrix's Jacobian rows): what the gusts add beyond the blocks'
    share of them (`gusts.gust_meat`)."""
    n_blocks = int(block.max()) + 1
    n_p = len(theta)
    rows = _score_rows(n_seg, seg, weights, instrument_row, theta, cos_angle, aero, extra, aux)
    scores = np.zeros((n_blocks, n_p))
    for a in np.flatnonzero(np.any(rows != 0, axis=0)):
        scores[:, a] = np.bincount(block, weights=rows[:, a] * residual, minlength=n_blocks)
    scores = scores[:, free_idx]
    p = len(free_idx)
    meat = scores.T @ scores * n_blocks / max(n_blocks - p, 1)
    if extra_meat is not None:
        meat = meat + extra_meat[np.ix_(free_idx, free_idx)]
    if gusts is not None and gusts[2] is not None:
        speed, distance, model, jacobian = gusts
        meat = meat + gust_meat(rows[:, free_idx], jacobian[:, free_idx], normal, speed, distance, block, model,
                                n_blocks / max(n_blocks - p, 1))
    inverse = _informed_inverse(normal)
    informed = free_idx[np.isfinite(np.diag(inverse))]
    seen = np.isfinite(np.diag(inverse))
    cov = np.full((n_p, n_p), np.nan)
    cov[np.ix_(informed, informed)] = (inverse[np.ix_(seen, seen)] @ meat[np.ix_(seen, seen)]
                                       @ inverse[np.ix_(seen, seen)].T)
    return cov


def _gust_model(theta, cov, n_seg, n_wind, settings):
    """The gusts' residual covariance (`gusts.gust_covariance`) for the fitted c_d A and mean wind,
    E|w|² its square plus its variance from ``cov``; None without wind columns (no GPS track: the
    wind is not modelled at all)."""
    if not n_wind:
        return None
    cda = theta[n_seg + 1]
    wind = theta[n_seg + 2:n_seg + 4] / cda
    mean_square = float(np.sum(wind ** 2) + np.sum(np.nan_to_num(np.diag(cov)[n_seg + 2:n_seg + 4])) / cda ** 2)
    return gust_covariance(cda, mean_square, settings.gust_intensity, settings.gust_length_m)


def _headless_wind_covariance(theta, cov, n_seg, seg, headless, speed_mps, score_rows, normal, seen):
    """What the head wind leaves in the parameters' covariance [n_p x n_p] from the samples without
    a heading (their wind columns 0): per segment one unknown head wind h_j over its headless
    samples, the fitted mean wind's component along a direction the log does not give, with
    E h_j² = (|w|² + tr Σ_w) / 2, the mean of (w·u)² over the directions u and the wind's own
    variance Σ_w from ``cov`` (an unidentified wind keeps its prior's). It is one value over the
    segment's headless samples (as the gradient's bias: conservative where the road turns in the
    outage) and independent between segments. It adds ρ c_d A v_k h_j to their force, which moves
    the fitted parameters by N⁻¹ (Σ_k w_k z_k ρ c_d A v_k) h_j (a "consider" parameter, as a held
    auxiliary power: ``score_rows`` the samples' w_k z_k, ``normal`` the fit's with its priors,
    ``seen`` the parameters it solved for)."""
    cda = theta[n_seg + 1]
    wind = theta[n_seg + 2:n_seg + 4] / cda
    mean_square = 0.5 * float(np.sum(wind ** 2) + np.sum(np.nan_to_num(np.diag(cov)[n_seg + 2:n_seg + 4])) / cda ** 2)
    force_per_mps = np.where(headless, AIR_DENSITY_KGPM3 * cda * speed_mps, 0.0)
    source = np.zeros((len(theta), n_seg))
    for a in np.flatnonzero(seen):
        source[a] = np.bincount(seg, weights=score_rows[:, a] * force_per_mps, minlength=n_seg)
    response = np.linalg.lstsq(normal[np.ix_(seen, seen)], source[seen], rcond=None)[0]
    out = np.zeros((len(theta), len(theta)))
    out[np.ix_(seen, seen)] = mean_square * response @ response.T
    return out


def _solve_positive_aux(data, theta0, free, aux_index, settings, prior, instrument, floor, held=None):
    """`_solve` with every auxiliary power P_j >= 0 (active set: a P_j the unconstrained fit puts
    below 0 is held at 0 and the rest fitted again; ``held`` ones from the start). Returns what
    `_solve` returns, the normal matrix over all ``free`` parameters (a held P_j's prior width stays
    in the covariance)."""
    f, x, c, q, ex, aux, seg, m = data
    held = np.zeros(len(theta0), bool) if held is None else held.copy()
    theta = theta0.copy()
    theta[held] = 0.0
    while True:
        theta, weights, normal, residual, regressor, row = _solve(f, x, c, q, ex, aux, seg, m, theta, free & ~held,
                                                                  settings, prior=prior, instrument=instrument,
                                                                  floor=floor)
        negative = aux_index[theta[aux_index] < 0]
        if not len(negative):
            break
        held[negative] = True
        theta = theta.copy()
        theta[held] = 0.0
    if held.any():
        normal, _ = _normal_equations(x, x if instrument is None else instrument, c, q, ex, aux, seg, theta, m,
                                      weights, residual)
        normal = (normal + np.diag(prior[1]))[np.ix_(free, free)]
    return theta, weights, normal, residual, regressor, row


SLOPE_SHARE_FLOOR = 1e-3
"""The least factor `_biweight_slope_share` gives a segment."""


def _biweight_slope_share(residual, weights, seg, n_seg, tuning):
    """Per segment, the mean slope psi'(u) of Tukey's psi(u) = u (1 - u²)² over its mean weight
    psi(u)/u: the factor that turns the reweighted least squares' normal matrix into the robust
    fit's own (its sandwich's bread, sum psi'(u_k) z_k x_k^T). Without it the covariance of a
    biweight fit is too small (stated 0.85 of the spread of the masses over 100 synthetic drives).
    A fit left with no weighted sample gets the floor everywhere, as a segment whose samples all
    lie beyond the biweight's reach."""
    used = weights > 0
    if not used.any():
        return np.full(n_seg, SLOPE_SHARE_FLOOR)
    scale = 1.4826 * np.median(np.abs(residual[used] - np.median(residual[used])))
    u = residual / (tuning * max(scale, 1e-9))
    slope = np.where(np.abs(u) < 1, (1 - u * u) * (1 - 5 * u * u), 0.0)
    share = np.bincount(seg, weights=slope, minlength=n_seg) / np.maximum(np.bincount(seg, weights=weights,
                                                                                        minlength=n_seg), 1e-12)
    return np.clip(share, SLOPE_SHARE_FLOOR, 1.0)


def fit_joint(force, excess, cos_angle, aero, time_s, bounds, usable, vehicle, settings: JointSettings = JointSettings(),
              regressor_name: str = "", instrument=None, wind_regressors=None, offset_regressor=None,
              aux_regressor=None, aux_prior_w=None, regressor_response: bool = False) -> JointFit:
    """Masses of the segments ``bounds`` ([start, end) index pairs) and the shared c_r, c_d·A from
    the samples in ``usable`` (see the module docstring). Coefficients the drive cannot identify
    (relative std above ``max_relative_std``, a non-physical value, or a singular system) are fixed
    at the vehicle file's value; their datasheet uncertainty then enters each mass.

    ``wind_regressors`` (n, 2): -rho v u_east, -rho v u_north [kg/m²·…] with u the unit vector of
    travel (`wind_regressors`); given, the drive's wind (east, north) [m/s] is fitted with them,
    c_d A w: the head wind's linear term of the drag, ½ rho c_d A (v + h)² ≈ ½ rho c_d A v² +
    rho c_d A v h with h = -w·u. A wind that is not modelled reads as mass wherever the route
    turns against it (measured: +11 % on one segment of the accuracy matrix). A sample whose row is
    NaN (no heading: a GPS outage, a track too short) is left out where its segment has
    ``min_samples`` with a heading: it holds a drag the fit does not model, and in an outage the
    gradient has no GPS height either. A segment with fewer is fitted with them, their wind columns
    0: its head wind there is one unknown, the fitted wind's component along a heading the log does
    not give, and its drag's share of the masses is in their covariance
    (`_headless_wind_covariance`), rather than the segment left to the LS of (9), which models no
    wind, no offset and no road load of the drive at all.

    ``offset_regressor`` (n,): the wheel force per unit of engine torque offset, as a fraction of
    the reference torque [N] (`offset_regressor`); given, a constant offset of the torque report
    is fitted (prior ``torque_offset_uncertainty``): J1939's actual torque is a percentage of the
    reference torque with an offset of its own (friction model), which reads as mass in proportion
    to the gear ratio.

    ``aux_regressor`` (n,): the wheel force per watt of engine power taken before the driveline
    [N/W] (`aux_power_regressor`, η/v); given (and ``aux_power_sigma_w`` > 0), an auxiliary power
    P_j >= 0 is fitted per segment (half-normal prior of that width): an auxiliary running on most
    of a segment is not rejected by the robust weights and reads as mass. Where the drive cannot
    tell P_j from the mass, the prior's width is in that mass's covariance.

    ``aux_prior_w`` (per segment [W], NaN: the default): the 1-sigma of the auxiliary power the
    force still holds where the drive cannot resolve it, for the covariance of a power held at 0
    (default ``aux_power_sigma_w``, the whole accessories' load): where the log's own estimate of
    the accessories' torque was taken off the force, what is left is that estimate's error. The fit
    and which powers it resolves keep ``aux_power_sigma_w``, so no estimate moves.

    ``regressor_response``: also return how each mass moves per unit regressor error at each sample
    (`JointFit.regressor_response`, samples x segments: some 200 MB for a day at 10 Hz and 30
    segments, so only where a gradient posterior will use it)."""
    n_seg = len(bounds)
    seg_of = np.full(len(force), -1)
    for j, (start, end) in enumerate(bounds):
        seg_of[start:end] = j
    n_wind = 0 if wind_regressors is None else 2
    headless = np.zeros(len(force), bool)
    columns = []
    if wind_regressors is not None:
        wind_columns = np.asarray(wind_regressors, dtype=float)
        headless = ~np.isfinite(wind_columns).all(axis=1)
        columns.append(np.where(headless[:, None], 0.0, wind_columns))
    if offset_regressor is not None:
        columns.append(np.asarray(offset_regressor, dtype=float)[:, None])
    extra_all = np.column_stack(columns) if columns else np.zeros((len(force), 0))
    n_extra = extra_all.shape[1]
    ok = usable & (seg_of >= 0) & np.isfinite(force) & np.isfinite(excess) & np.isfinite(cos_angle) & np.isfinite(aero)
    ok &= np.isfinite(extra_all).all(axis=1)
    fit_aux = aux_regressor is not None and settings.aux_power_sigma_w > 0
    if fit_aux:
        ok &= np.isfinite(aux_regressor)
    if instrument is not None:
        ok &= np.isfinite(instrument)
    headed = np.bincount(seg_of[ok & ~headless], minlength=n_seg) >= settings.min_samples
    ok &= ~(headless & headed[np.clip(seg_of, 0, None)])
    counts = np.bincount(seg_of[ok], minlength=n_seg)
    enough = counts >= settings.min_samples
    ok &= enough[np.clip(seg_of, 0, None)]
    kept = np.flatnonzero(enough)
    remap = np.full(n_seg, -1)
    remap[kept] = np.arange(len(kept))
    result = JointFit(masses_kg=np.full(n_seg, np.nan), mass_std_kg=np.full(n_seg, np.nan),
                      coefficients={"rolling_resistance_coefficient": vehicle.rolling_resistance_coefficient,
                                    "drag_area_m2": vehicle.drag_coefficient * vehicle.frontal_area_m2},
                      coefficient_std={c: None for c in COEFFICIENTS}, identified={c: False for c in COEFFICIENTS},
                      reasons={c: "no segment with enough samples" for c in COEFFICIENTS},
                      sensitivity_kg=np.zeros(n_seg), weights=np.zeros(len(force)),
                      regressor_values=np.zeros(len(force)), samples=counts, outliers=0,
                      regressor=regressor_name, mass_covariance_kg2=np.full((n_seg, n_seg), np.nan))
    if len(kept) == 0:
        return result
    f, x, c, q, ex = force[ok], excess[ok], cos_angle[ok], aero[ok], np.ascontiguousarray(extra_all[ok])
    aux = np.asarray(aux_regressor, dtype=float)[ok] if fit_aux else np.zeros(len(f))
    seg = remap[seg_of[ok]]
    t = time_s[ok]
    speed_all = np.sqrt(2 * np.clip(np.nan_to_num(aero), 0, None) / AIR_DENSITY_KGPM3)
    speed, distance = speed_all[ok], distance_m(time_s, speed_all)[ok]
    block_start = np.array([t[seg == j].min() for j in range(len(kept))])
    block_local = np.floor((t - block_start[seg]) / settings.block_s).astype(np.int64)
    _, block = np.unique(seg * 1_000_000 + block_local, return_inverse=True)
    m = len(kept)
    n_aux = m if fit_aux else 0
    theta0 = np.concatenate([np.zeros(m), [result.coefficients["rolling_resistance_coefficient"],
                                           result.coefficients["drag_area_m2"]], np.zeros(n_extra + n_aux)])
    regressor0 = x + G_MPS2 * theta0[m] * c
    theta0[:m] = (np.bincount(seg, weights=regressor0 * (f - theta0[m + 1] * q), minlength=m)
                  / np.bincount(seg, weights=regressor0 ** 2, minlength=m))
    free = np.ones(len(theta0), bool)
    aux_index = np.arange(m + 2 + n_extra, len(theta0))
    centre = theta0.copy()
    prior_std = np.concatenate([np.full(m, np.inf), [settings.rolling_resistance_uncertainty * theta0[m],
                                                     settings.drag_area_uncertainty * theta0[m + 1]],
                                np.full(n_wind, settings.wind_sigma_mps * theta0[m + 1]),
                                np.full(n_extra - n_wind, settings.torque_offset_uncertainty),
                                np.full(n_aux, settings.aux_power_sigma_w)])
    floor = np.where(np.arange(len(theta0)) >= m + 2 + n_extra, 1.0, 1e-9)  # a watt of auxiliary power
    z = None if instrument is None else instrument[ok]
    try:
        # the data alone: the noise level per unit of the normal matrix, from the block-robust covariance
        # (the auxiliary powers need their prior: left at 0 here)
        data_free = free.copy()
        data_free[aux_index] = False
        theta, weights, normal, residual, regressor, row = _solve(f, x, c, q, ex, aux, seg, m, theta0, data_free,
                                                                  settings, instrument=z, floor=floor)
        sandwich = _block_covariance(normal, np.flatnonzero(data_free), m, seg, block, weights, residual, row, theta,
                                     c, q, ex, aux)
        ratio = np.diag(sandwich)[:m] / np.abs(np.diag(_informed_inverse(normal))[:m])
        noise_var = float(np.median(ratio[np.isfinite(ratio)])) if np.isfinite(ratio).any() else np.nan
    except np.linalg.LinAlgError:
        noise_var = np.nan
    if not noise_var > 0:  # the data alone did not converge (every sample weighted out): the first guess's scatter
        noise_var = float(np.var(f - theta0[:m][seg] * (x + G_MPS2 * theta0[m] * c) - theta0[m + 1] * q))
    # the vehicle file's values as a prior of datasheet width: a coefficient the drive cannot tell
    # stays near the datasheet value and its datasheet uncertainty goes into every mass
    precision = np.where(np.isfinite(prior_std), noise_var / prior_std ** 2, 0.0)
    data = (f, x, c, q, ex, aux, seg, m)
    unidentified = np.zeros(len(theta0), bool)
    for _ in range(2):
        # an auxiliary power the drive cannot tell from the mass stays at its prior's mode, 0, with
        # the prior's width in the covariance: fitted, P >= 0 would take up noise one way only
        theta, weights, normal, residual, regressor, row = _solve_positive_aux(
            data, theta0, free, aux_index, settings, (centre, precision), z, floor, held=unidentified)
        share = _biweight_slope_share(residual, weights, seg, m, settings.robust_tuning)
        bread, _ = _normal_equations(x, x if z is None else z, c, q, ex, aux, seg, theta, m, weights * share[seg],
                                     residual)
        blocks_only = _block_covariance(bread + np.diag(precision), np.flatnonzero(free), m, seg, block, weights,
                                        residual, row, theta, c, q, ex, aux, extra_meat=noise_var * np.diag(precision))
        gusts = (speed, distance, _gust_model(theta, blocks_only, m, n_wind, settings),
                 _score_rows(m, seg, share[seg], regressor, theta, c, q, ex, aux))
        cov = _block_covariance(bread + np.diag(precision), np.flatnonzero(free), m, seg, block, weights, residual,
                                row, theta, c, q, ex, aux, extra_meat=noise_var * np.diag(precision), gusts=gusts)
        # which auxiliary powers the drive resolves stays the blocks' question, so the gusts'
        # term moves the sigmas only, not the fit (with a held power, the masses would move)
        wide = aux_index[~(np.sqrt(np.diag(blocks_only)[aux_index])
                           < settings.max_prior_fraction * settings.aux_power_sigma_w)]
        if unidentified[wide].all():
            break
        unidentified[wide] = True
    statistical = cov
    headless_used = bool(n_wind and headless[ok].any())
    # the converged fit's normal matrix without its priors and its samples' score rows, for what the
    # held powers, the headless samples' wind and the regressor's errors leave in the masses
    plain = (_normal_equations(x, x if z is None else z, c, q, ex, aux, seg, theta, m, weights, residual)[0]
             if unidentified.any() or headless_used or regressor_response else None)
    score_rows = (_score_rows(m, seg, weights, row, theta, c, q, ex, aux)
                  if headless_used or regressor_response else None)
    if unidentified.any():
        # like the torque gain, an auxiliary power the drive cannot resolve is a systematic term of
        # the mass's uncertainty, not a want of excitation: out of the statistical covariance
        seen = free & ~unidentified
        seen_normal = (bread + np.diag(precision))[np.ix_(seen, seen)]
        statistical = _block_covariance(seen_normal, np.flatnonzero(seen), m, seg, block, weights, residual, row,
                                        theta, c, q, ex, aux, extra_meat=noise_var * np.diag(precision), gusts=gusts)
        # a held power is 0 in the fit whatever the data say, so what it leaves in the estimates is
        # the fit's response to it times its prior's width: the force still holds a power P_j
        # P_j η / v, and the fitted parameters move by N⁻¹ (Σ w z x_j) P_j (a "consider"
        # parameter); its width is what the force still holds of the accessories (`aux_prior_w`):
        # where the log's own estimate took them off, not the whole accessories' load
        held = np.flatnonzero(unidentified)
        width = np.full(m, np.nan) if aux_prior_w is None else np.asarray(aux_prior_w, dtype=float)[kept]
        width = np.where(np.isfinite(width), width, settings.aux_power_sigma_w)[held - aux_index[0]]
        response = np.linalg.lstsq((plain + np.diag(precision))[np.ix_(seen, seen)], plain[np.ix_(seen, unidentified)],
                                   rcond=None)[0]
        cov = statistical.copy()
        cov[np.ix_(seen, seen)] += (response * width ** 2) @ response.T
        cov[held, held] = width ** 2
    if headless_used:
        cov = cov + _headless_wind_covariance(theta, cov, m, seg, headless[ok], speed, score_rows,
                                              plain + np.diag(precision), free & ~unidentified)
    result.headless_samples = np.bincount(seg_of[ok & headless], minlength=n_seg)
    scale = np.sqrt(np.abs(np.diag(normal)))
    informative = scale > 0  # a segment without a single usable sample has an empty row
    condition = float(np.linalg.cond(normal[np.ix_(informative, informative)]
                                     / np.outer(scale[informative], scale[informative])))
    if regressor_response:
        at_bound = np.zeros(len(theta), bool)
        at_bound[aux_index] = theta[aux_index] == 0  # held at 0 (P >= 0): a small change leaves it there
        result.regressor_response = np.zeros((len(force), n_seg))
        result.regressor_response[np.ix_(np.flatnonzero(ok), kept)] = _regressor_response(
            plain, score_rows, theta, seg, m, precision, free & ~unidentified & ~at_bound)
    reasons = {}
    for index, name in ((m, COEFFICIENTS[0]), (m + 1, COEFFICIENTS[1])):
        std = float(np.sqrt(cov[index, index]))
        relative = std / abs(theta[index])
        if std > settings.max_prior_fraction * prior_std[index] or relative > settings.max_relative_std:
            free[index] = False
            reasons[name] = (f"not identifiable on this drive (std {100 * relative:.1f} %, "
                             f"{100 * std / prior_std[index]:.0f} % of the datasheet's): stays near the vehicle file")
    result.condition = condition
    result.masses_kg[kept] = theta[:m]
    result.mass_std_kg[kept] = np.sqrt(np.diag(statistical)[:m])
    result.mass_covariance_kg2[np.ix_(kept, kept)] = statistical[:m, :m]
    result.sensitivity_kg[kept] = np.sqrt(np.maximum(np.diag(cov)[:m] - np.diag(statistical)[:m], 0.0))
    result.masses_kg[~np.isfinite(result.mass_std_kg)] = np.nan
    for index, name in ((m, COEFFICIENTS[0]), (m + 1, COEFFICIENTS[1])):
        result.coefficients[name] = float(theta[index])
        result.identified[name] = bool(free[index])
        result.coefficient_std[name] = float(np.sqrt(cov[index, index]))
        result.reasons[name] = reasons.get(name, "identified")
    if n_wind:
        cda = theta[m + 1]
        wind = theta[m + 2:m + 4] / cda
        wind_std = np.sqrt(np.diag(cov)[m + 2:m + 4]) / abs(cda)
        identified = bool(np.all(np.sqrt(np.diag(cov)[m + 2:m + 4]) < settings.max_prior_fraction * prior_std[m + 2:m + 4]))
        result.coefficients.update(wind_east_mps=float(wind[0]), wind_north_mps=float(wind[1]))
        result.coefficient_std.update(wind_east_mps=float(wind_std[0]), wind_north_mps=float(wind_std[1]))
        result.identified.update(wind_east_mps=identified, wind_north_mps=identified)
        reason = "identified" if identified else (f"not identifiable on this drive (the route does not turn enough): "
                                                  f"its {settings.wind_sigma_mps:g} m/s prior is in every mass")
        result.reasons.update(wind_east_mps=reason, wind_north_mps=reason)
    if offset_regressor is not None:
        index = m + 2 + n_wind
        std = float(np.sqrt(cov[index, index]))
        identified = std < settings.max_prior_fraction * prior_std[index]
        result.coefficients["torque_offset"] = float(theta[index])
        result.coefficient_std["torque_offset"] = std
        result.identified["torque_offset"] = bool(identified)
        result.reasons["torque_offset"] = "identified" if identified else (
            f"not identifiable on this drive (too few gears): its {100 * settings.torque_offset_uncertainty:g} % "
            f"prior is in every mass")
    if fit_aux:
        std = np.sqrt(np.diag(cov)[aux_index])
        result.aux_power_w, result.aux_power_std_w = np.full(n_seg, np.nan), np.full(n_seg, np.nan)
        result.aux_identified = np.zeros(n_seg, bool)
        result.aux_power_w[kept], result.aux_power_std_w[kept] = theta[aux_index], std
        result.aux_identified[kept] = (std < settings.max_prior_fraction * settings.aux_power_sigma_w) & ~unidentified[aux_index]
    result.slope_share = np.full(n_seg, np.nan)
    result.slope_share[kept] = share
    result.weights[ok] = weights
    result.rejected_share = np.full(n_seg, np.nan)
    result.rejected_share[kept] = np.bincount(seg, weights=(weights == 0).astype(float), minlength=m) / np.bincount(
        seg, minlength=m)
    result.regressor_values[ok] = regressor
    result.outliers = int(np.sum(weights == 0))
    return result


def wind_regressors(speed_mps, east_m, north_m, time_s, window_s: float = 5.0) -> np.ndarray:
    """(n, 2) columns -rho v u_east, -rho v u_north of the head wind's drag term [kg/m³ · m/s],
    u the unit vector of travel from the track's positions over ``window_s`` (NaN where the truck
    stands or positions are missing)."""
    from ..road_load import AIR_DENSITY_KGPM3
    time_s = np.asarray(time_s, dtype=float)
    steps = np.diff(time_s)
    half = max(1, int(round(window_s / 2 / (np.median(steps[steps > 0]) if np.any(steps > 0) else 1.0))))
    east, north = np.asarray(east_m, dtype=float), np.asarray(north_m, dtype=float)
    d_east = np.full(len(east), np.nan)
    d_north = np.full(len(east), np.nan)
    d_east[half:-half] = east[2 * half:] - east[:-2 * half]
    d_north[half:-half] = north[2 * half:] - north[:-2 * half]
    length = np.hypot(d_east, d_north)
    speed = np.asarray(speed_mps, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        moving = length > 0.5 * speed * window_s
        u = np.where(moving[:, None], np.column_stack([d_east, d_north]) / length[:, None], np.nan)
    return -AIR_DENSITY_KGPM3 * speed[:, None] * u


def offset_regressor(wheel_force_n, engine_torque_nm, reference_torque_nm: float) -> np.ndarray:
    """Wheel force [N] that a torque offset of the whole reference torque would add, per sample:
    F_wheel / T_engine x T_ref (the driveline's ratio and efficiency over the wheel radius);
    NaN where the engine gives less than 5 % of its reference torque."""
    torque = np.asarray(engine_torque_nm, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.asarray(wheel_force_n, dtype=float) / torque * reference_torque_nm
    return np.where(torque > 0.05 * reference_torque_nm, out, np.nan)


def aux_power_regressor(wheel_force_n, engine_torque_nm, engine_speed_rpm) -> np.ndarray:
    """Wheel force per watt of engine power taken before the driveline [N/W]: F_wheel / (T_engine
    ω_engine), i.e. η / v through the gear the truck is in (a power P at the crankshaft is a
    torque P / ω there); NaN where the engine gives no torque or stands."""
    torque = np.asarray(engine_torque_nm, dtype=float)
    omega = np.asarray(engine_speed_rpm, dtype=float) * np.pi / 30.0
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.asarray(wheel_force_n, dtype=float) / (torque * omega)
    return np.where((torque > 0) & (omega > 0), out, np.nan)
