"""Vehicle mass (paper §2.2.2, equations (9)-(14)): the data filter, then least squares, recursive
least squares with forgetting and the damped Levenberg-Marquardt form, one mass per segment
between stops, each with an uncertainty; and the joint estimate (``joint``): masses of all
segments with the drive's c_r and c_d·A, from the accelerometer where there is one (so the mass
does not depend on the gradient estimate), calibrated by a known mass (``calibration``).

Public: `estimate_mass(frame, vehicle, filter_settings, segment_settings, joint_settings,
known_masses) -> MassResult`; the
pipeline's stage, which adds ``mass_kg`` (and ``mass_ls_kg``, ``mass_rls_kg``, ``mass_lm_kg``), is
`analysis.mass.stage.mass_stage`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..engine_torque import REPORTED, driveline_torque_nm, parasitic_torque_nm, torque_used
from ..gradient.posterior import GradientPosterior
from ..road_load import G_MPS2
from . import calibration
from .joint import JointFit, JointSettings, aux_power_regressor, fit_joint, offset_regressor, wind_regressors
from .regression import FilterSettings, Regression, build_regression
from .segments import SegmentSettings, estimate_segment, segment_bounds, split_at_payload_changes
from .unmodelled import ls_unmodelled_kg

__all__ = ["estimate_mass", "MassResult", "FilterSettings", "SegmentSettings", "JointSettings"]


@dataclass
class MassResult:
    segments: list[dict]
    """Per segment: start_s, end_s, n_samples, mass_{ls,rls,lm}_kg, uncertainty_kg,
    reported_mass_kg, status, reason."""
    columns: dict[str, np.ndarray]
    """mass_kg (LS of 'ok' segments, else NaN), mass_ls_kg, mass_rls_kg, mass_lm_kg."""
    regression: Regression
    notes: list[str] = field(default_factory=list)
    road_load: dict = field(default_factory=dict)
    """The joint fit: regressor, c_r and c_d·A (value, std, identified, reason), torque gain."""
    joint: JointFit | None = None
    drive: pd.DataFrame | None = None
    """The drive's time_s [s] (and the truck's own reported_mass_kg), for the figure."""
    true_mass_kg: tuple[float, ...] | None = None
    """A weighed total mass [kg], one or one per segment, for the figure."""
    engine_torque: str = ""
    """Which engine torque the force came from (`engine_torque.torque_used`)."""

    def summary(self) -> dict:
        """The segments, samples used, the joint road-load fit, why samples were left out, the
        engine torque used, notes."""
        return {"segments": self.segments, "samples_used": int(self.regression.usable.sum()),
                "road_load": self.road_load, "rejected_by": self.regression.rejected,
                "engine_torque": self.engine_torque, "notes": self.notes}

    def problem(self) -> str | None:
        if self.segments and not any("ok" in (s["status"], s.get("mass_joint_status")) for s in self.segments):
            return "no segment has enough excitation for a confident mass (see the report's mass chapter)"
        return None


def estimate_mass(frame: pd.DataFrame, vehicle, filter_settings: FilterSettings = FilterSettings(),
                  segment_settings: SegmentSettings = SegmentSettings(),
                  joint_settings: JointSettings = JointSettings(), known_masses: dict[int, float] | None = None,
                  gradient_posteriors: tuple[GradientPosterior, ...] = ()) -> MassResult:
    """Per-segment masses [kg] of a signals table (see `MassResult`); ``known_masses`` {segment
    index from 0: kg} calibrates the torque gain; ``gradient_posteriors`` the gradient stage's
    (`GradientResult.posteriors`): the one of the gradient fitted on gives the gradient regressor's
    share of the masses' covariance. UserError if columns are missing.

    Where ``gradient_pct`` itself rests on a mass (the force balance standing in for a missing
    IMU, `gradient.force_balance`), the gradient stage also writes ``gradient_mass_pct``, the
    estimate without it, and the mass is fitted on that: on its own force-balance gradient any
    mass fits its torque, and would look confident."""
    frame = _with_gradient_std(frame)
    own_gradient_error = False
    if "gradient_mass_pct" in frame.columns and frame["gradient_mass_pct"].notna().any():
        std = frame["gradient_mass_std_pct"] if "gradient_mass_std_pct" in frame.columns else np.nan
        frame = frame.assign(gradient_pct=frame["gradient_mass_pct"], gradient_std_pct=std)
        own_gradient_error = True
    # a gradient that rests on a mass (`gradient_mass_pct`, the force balance's) has no posterior
    # of its own errors: the smoother's is conditional on the mass put in
    posterior = None if own_gradient_error else _gradient_posterior(frame, gradient_posteriors)
    regression = build_regression(frame, vehicle, filter_settings)
    time_s = frame["time_s"].to_numpy(dtype=float)
    speed = frame["speed_mps"].to_numpy(dtype=float)
    reported = frame["reported_mass_kg"].to_numpy(dtype=float) if "reported_mass_kg" in frame else None
    max_mass = vehicle.curb_mass_kg + 2.0 * (vehicle.max_payload_kg or 3.0 * vehicle.curb_mass_kg)
    columns = {name: np.full(len(frame), np.nan) for name in ("mass_kg", "mass_ls_kg", "mass_rls_kg", "mass_lm_kg")}
    segments = []
    bounds = split_at_payload_changes(segment_bounds(time_s, speed, segment_settings), time_s, speed,
                                      *_change_regression(regression, vehicle), segment_settings)
    for start, end in bounds:
        part = slice(start, end)
        estimate = estimate_segment(regression.phi[part], regression.y[part], vehicle.curb_mass_kg, max_mass,
                                    segment_settings)
        if estimate["mass_ls_kg"] is not None:
            columns["mass_ls_kg"][part] = estimate["mass_ls_kg"]
            columns["mass_rls_kg"][part] = estimate.pop("rls_path")
            columns["mass_lm_kg"][part] = estimate.pop("lm_path")
            if estimate["status"] == "ok":
                columns["mass_kg"][part] = estimate["mass_ls_kg"]
        estimate.pop("rls_path", None)
        estimate.pop("lm_path", None)
        moving_report = None
        if reported is not None:
            values = reported[part][np.isfinite(reported[part]) & (speed[part] > 1.0)]
            moving_report = float(np.median(values)) if len(values) else None
        segments.append({"start_s": float(time_s[start]), "end_s": float(time_s[end - 1]), **estimate,
                         "reported_mass_kg": moving_report})
    notes = []
    if regression.usable.sum() == 0:
        worst = max(regression.rejected, key=regression.rejected.get)
        notes.append(f"no sample passes the data filter (most fail: {worst}, {regression.rejected[worst]} "
                     f"of {len(frame)}): no mass estimated")
    wind = _wind_regressors(frame, speed, time_s) if joint_settings.fit_wind else None
    offset = _offset_regressor(frame, regression, vehicle) if joint_settings.fit_torque_offset else None
    aux = _aux_regressor(frame, regression) if joint_settings.aux_power_sigma_w > 0 else None
    if wind is not None:
        notes.append("the drive's wind fitted with the masses from the heading along the GPS track")
    engine_torque = torque_used(frame)
    if engine_torque != REPORTED:
        notes.append(f"engine torque: {engine_torque}")
    aux_prior = _aux_prior_w(frame, regression, bounds, joint_settings) if aux is not None else None
    carried = None
    if own_gradient_error and "gradient_mass_scale_rel_std" in frame.columns:
        scale_std = frame["gradient_mass_scale_rel_std"].to_numpy(dtype=float)
        carried = np.array([np.nanmedian(scale_std[start:end]) if np.isfinite(scale_std[start:end]).any() else 0.0
                            for start, end in bounds])
    road_load, joint = _joint(regression, time_s, bounds, vehicle, joint_settings, known_masses or {}, segments,
                              columns, max_mass, notes, segment_settings, wind,
                              offset, aux, aux_prior, speed,
                              posterior, own_gradient_error, carried)
    return MassResult(segments=segments, columns=columns, regression=regression, notes=notes, road_load=road_load,
                      joint=joint, engine_torque=engine_torque)


def _with_gradient_std(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with ``gradient_std_pct``, the stated 1-sigma of its ``gradient_pct`` [%-pt]: the
    smoother's ``gradient_smooth_std_pct`` where ``gradient_pct`` is the smoother's gradient, else
    NaN (the paper's fusion, the barometer, the map and a gradient given from outside state none)."""
    if "gradient_std_pct" in frame.columns:
        return frame
    std = np.nan
    if {"gradient_pct", "gradient_smooth_pct", "gradient_smooth_std_pct"} <= set(frame.columns):
        same = np.array_equal(frame["gradient_pct"].to_numpy(dtype=float),
                              frame["gradient_smooth_pct"].to_numpy(dtype=float), equal_nan=True)
        std = frame["gradient_smooth_std_pct"] if same else np.nan
    return frame.assign(gradient_std_pct=std)


def _gradient_posterior(frame: pd.DataFrame, posteriors) -> GradientPosterior | None:
    """Of ``posteriors`` (`gradient.posterior`), the one of the table's ``gradient_pct``; None where
    none is that gradient's."""
    for posterior in posteriors:
        if posterior.describes(frame["gradient_pct"].to_numpy(dtype=float)):
            return posterior
    return None


def gradient_regressor_covariance_kg2(fit: JointFit, posterior: GradientPosterior, cos_angle) -> np.ndarray:
    """Covariance [kg²] (segments × segments) of the masses' errors from the gradient regressor's:
    a gradient error e_k (tan α) at sample k moves the regressor by g cos³α e_k and every mass by
    the fit's response to it (`JointFit.regressor_response`: through c_r, c_d·A and the wind too),
    and the sums' covariance is the smoother's own posterior over the grid, wᵀ P w
    (`GradientPosterior.sum_covariance`): the gradient's errors change sign along a segment, which
    one error fully correlated over it does not hold. 0 for a segment without a mass."""
    if fit.regressor_response is None:  # no segment was fitted
        return np.zeros((len(fit.masses_kg), len(fit.masses_kg)))
    cube = np.nan_to_num(np.asarray(cos_angle, dtype=float), nan=1.0) ** 3
    sensitivity = np.nan_to_num(fit.regressor_response) * (G_MPS2 * cube)[:, None]
    sensitivity[:, ~np.isfinite(fit.masses_kg)] = 0.0
    return posterior.sum_covariance(sensitivity)


def regressor_bias_kg(fit: JointFit, regressor_std, bounds) -> np.ndarray:
    """Mass error [kg] per segment of a systematic regressor error sigma_psi (IMU bias calibration
    or gradient bias): dm = m sigma_psi sum(w phi) / sum(w phi^2) over the segment's used samples."""
    out = np.zeros(len(bounds))
    for j, (start, end) in enumerate(bounds):
        w = fit.weights[start:end]
        phi = fit.regressor_values[start:end]
        if np.isfinite(fit.masses_kg[j]) and np.sum(w * phi * phi) > 0:
            sigma = float(np.sum(w * regressor_std[start:end]) / max(np.sum(w), 1e-12))
            out[j] = abs(fit.masses_kg[j]) * sigma * np.sum(w * phi) / np.sum(w * phi * phi)
    return out


def _change_regression(regression, vehicle):
    """(phi, y) for telling payload changes at short stops: the accelerometer's regressor where
    there is one (independent of the gradient estimate, whose error differs between stretches),
    else the gradient one."""
    if regression.excess_imu is None:
        return regression.phi, regression.y
    rolling = G_MPS2 * vehicle.rolling_resistance_coefficient * regression.cos_angle
    phi = np.where(regression.usable_imu, regression.excess_imu + rolling, np.nan)
    return phi, np.where(regression.usable_imu, regression.y, np.nan)


def _wind_regressors(frame, speed, time_s):
    """The joint fit's head-wind columns from the GPS track (None without positions)."""
    from ..geodesy import local_east_north_m
    if not {"latitude_deg", "longitude_deg"} <= set(frame.columns) or frame["latitude_deg"].isna().all():
        return None
    east, north = local_east_north_m(frame["latitude_deg"].to_numpy(dtype=float),
                                     frame["longitude_deg"].to_numpy(dtype=float))
    return wind_regressors(speed, east, north, time_s)


def _offset_regressor(frame, regression, vehicle):
    """The joint fit's torque-offset column (None without engine torque or a reference torque)."""
    reference = getattr(vehicle, "engine_reference_torque_nm", None)
    if not reference or "engine_torque_nm" not in frame.columns or regression.force is None:
        return None
    return offset_regressor(regression.force, _smoothed_torque(frame), reference)


def _aux_regressor(frame, regression):
    """The joint fit's auxiliary-power column (None without engine torque)."""
    if "engine_torque_nm" not in frame.columns or regression.force is None:
        return None
    return aux_power_regressor(regression.force, _smoothed_torque(frame), frame["engine_speed_rpm"].to_numpy(dtype=float))


def _aux_prior_w(frame, regression, bounds, settings):
    """Per segment, the 1-sigma [W] of the auxiliary power the force still holds where the log's
    SPN 2978 was taken off it (`engine_torque.parasitic_torque_nm`): its estimate's error,
    ``parasitic_estimate_uncertainty`` of the accessories' mean power over the segment's usable
    samples (NaN: none usable). None where the log has no such column: the whole accessories' load
    is still in the force."""
    parasitic = parasitic_torque_nm(frame)
    if parasitic is None:
        return None
    power = np.abs(parasitic) * frame["engine_speed_rpm"].to_numpy(dtype=float) * np.pi / 30.0
    out = np.full(len(bounds), np.nan)
    for j, (start, end) in enumerate(bounds):
        used = regression.usable[start:end] & np.isfinite(power[start:end])
        if used.any():
            out[j] = settings.parasitic_estimate_uncertainty * float(np.mean(power[start:end][used]))
    return out


def _smoothed_torque(frame):
    """The driveline's engine torque [Nm] (the force's) over the force's 1 s window, so that
    F_wheel / T_engine is the driveline's ratio."""
    torque = driveline_torque_nm(frame)
    window = max(1, int(round(1.0 / np.median(np.diff(frame["time_s"].to_numpy(dtype=float))))))
    return np.convolve(np.nan_to_num(torque), np.ones(window) / window, "same")


def _aux_power(fit: JointFit, j: int, gain: float) -> dict:
    """A segment's auxiliary power [W] and 1-sigma as the summary gives them (with the torque gain
    taken out like the masses'), and whether the drive identified it; empty where not fitted."""
    if fit.aux_power_w is None or not np.isfinite(fit.aux_power_w[j]):
        return {}
    return {"aux_power_w": float(fit.aux_power_w[j] / gain), "aux_power_std_w": float(fit.aux_power_std_w[j] / gain),
            "aux_power_identified": bool(fit.aux_identified[j])}


def _joint(regression, time_s, bounds, vehicle, settings, known, segments, columns, max_mass, notes,
           segment_settings, wind=None, offset=None, aux=None, aux_prior=None, speed=None, posterior=None,
           own_gradient_error=False, carried_relative=None):
    """Joint fit with the IMU regressor (else the gradient one), calibration, and per segment the
    chosen ``mass_kg`` and its total ``mass_uncertainty_kg``; the gradient-based joint fit too,
    for comparison. ``posterior``: the gradient's (`gradient.posterior`), for the gradient
    regressor's share of the masses' covariance; None: its stated σ as one error of each segment,
    shared by the drive's segments, or with ``own_gradient_error`` each segment's own, with
    ``carried_relative`` (per segment, relative) the share of the mass the force balance's gradient
    carried that its height sources did not pin (the scale state's σ), each segment's own too."""
    fits = {}
    if regression.excess_imu is not None:
        fits["imu"] = fit_joint(regression.force, regression.excess_imu, regression.cos_angle,
                                regression.aero_per_cda, time_s, bounds, regression.usable_imu, vehicle, settings, "imu",
                                instrument=regression.excess_gradient, wind_regressors=wind, offset_regressor=offset,
                                aux_regressor=aux, aux_prior_w=aux_prior)
    else:
        notes.append("no accelerometer with a calibrated bias (accel_x_mps2, imu_bias_mps2): mass from the "
                     "gradient-based regressor")
    fits["gradient"] = fit_joint(regression.force, regression.excess_gradient, regression.cos_angle,
                                 regression.aero_per_cda, time_s, bounds, regression.usable, vehicle, settings, "gradient",
                                 wind_regressors=wind, offset_regressor=offset, aux_regressor=aux,
                                 aux_prior_w=aux_prior, regressor_response=posterior is not None)
    chosen = fits.get("imu", fits["gradient"])
    gradient_bias = G_MPS2 * np.sin(np.arctan(segment_settings.gradient_bias_pct / 100))
    covariances = {}
    for name, fit in fits.items():
        if name == "imu" and regression.excess_imu_std is not None:
            regressor_std = np.nan_to_num(regression.excess_imu_std, nan=0.0)
        elif regression.excess_gradient_std is not None:
            # the gradient's own stated sigma, taken as fully correlated over the segment (its
            # errors are correlated over hundreds of metres; conservative over shorter scales)
            regressor_std = np.nan_to_num(regression.excess_gradient_std, nan=gradient_bias)
        else:
            regressor_std = np.full(len(time_s), gradient_bias)
        if name == "gradient" and posterior is not None:
            # the smoother's own correlation of the gradient's errors, within and between segments
            regressor_kg2 = gradient_regressor_covariance_kg2(fit, posterior, regression.cos_angle)
            covariances[name] = fit.mass_covariance_kg2 + np.diag(fit.sensitivity_kg ** 2) + regressor_kg2
            fit.sensitivity_kg = np.sqrt(fit.sensitivity_kg ** 2 + np.clip(np.diag(regressor_kg2), 0.0, None))
            continue
        bias_kg = regressor_bias_kg(fit, regressor_std, bounds)
        # the force balance's gradient (`gradient_mass_pct`) has its error through each segment's
        # own mass and scale state: a weighing tells the torque gain, not another segment's error
        shared_kg = np.zeros(len(bounds)) if name == "gradient" and own_gradient_error else bias_kg
        if name == "imu" and regression.excess_imu_shared_std is not None:
            shared = regression.excess_imu_shared_std
            shared_kg = regressor_bias_kg(fit, np.where(np.isfinite(shared), shared, regressor_std), bounds)
        own_kg = np.sqrt(np.clip(bias_kg ** 2 - shared_kg ** 2, 0.0, None))
        carried_kg = np.zeros(len(bounds))
        if name == "gradient" and carried_relative is not None:
            carried_kg = np.nan_to_num(fit.masses_kg * carried_relative)
            own_kg = np.hypot(own_kg, carried_kg)
        ramp_kg = np.zeros(len(bounds))
        if name == "imu" and regression.excess_imu_ramp_std is not None:
            ramp_kg = regressor_bias_kg(fit, np.nan_to_num(regression.excess_imu_ramp_std, nan=0.0), bounds)
        # for a weighing: a regressor error constant over a segment (the height source's slow drift
        # under the gradient) is one error of the drive, fully correlated across its segments (the
        # truth of the accuracy matrix's ideal no-imu drives, where the gradient is the mass's main
        # error: 1.6 % RMS shared by a drive's segments, 0.4 % their own); the IMU bias's error is
        # shared only as far as the smoother's cross-covariances say (`imu_bias_shared_std_mps2`),
        # the rest is each segment's own; an auxiliary power's prior the drive cannot resolve (the
        # fit's sensitivity) is the segment's own; so is the IMU bias's move over a standstill that
        # the smoother did not follow (`imu_bias_ramp_std_mps2`): it is the difference of the errors
        # either side of a stop, so a weighing before the stop tells nothing of it after
        covariances[name] = (fit.mass_covariance_kg2 + np.diag(fit.sensitivity_kg ** 2 + ramp_kg ** 2 + own_kg ** 2)
                             + np.outer(shared_kg, shared_kg))
        fit.sensitivity_kg = np.sqrt(fit.sensitivity_kg ** 2 + bias_kg ** 2 + ramp_kg ** 2 + carried_kg ** 2)
    gain_uncertainty = float(np.hypot(settings.torque_gain_uncertainty, settings.driveline_efficiency_uncertainty))
    results = {}
    for name, fit in fits.items():
        # the fit the masses come from must have the weighed segments (else the user hears so); the
        # other, for comparison, uses those it has a mass for
        own = known if fit is chosen else {j: kg for j, kg in known.items()
                                           if j < len(fit.masses_kg) and np.isfinite(fit.masses_kg[j])}
        results[name] = calibration.calibrate(fit.masses_kg, fit.mass_std_kg, fit.sensitivity_kg, own,
                                              gain_uncertainty, covariances[name])
    masses, total, gain = results[chosen.regressor]
    for j, (segment, (start, end)) in enumerate(zip(segments, bounds)):
        for name, (m, sigma, _) in results.items():
            segment[f"mass_{name}_kg"] = float(m[j]) if np.isfinite(m[j]) else None
            segment[f"mass_{name}_uncertainty_kg"] = float(sigma[j]) if np.isfinite(m[j]) else None
        mass, sigma = masses[j], total[j]
        status, reason = "ok", ""
        broken = chosen.rejected_share is not None and chosen.rejected_share[j] > settings.max_rejected_share
        if not np.isfinite(mass):
            status, reason = "no_excitation", f"only {int(chosen.samples[j])} samples for the joint fit"
        elif not (0.5 * vehicle.curb_mass_kg < mass < max_mass):
            status, reason = "implausible", f"joint mass {mass:.0f} kg outside {0.5 * vehicle.curb_mass_kg:.0f}.." \
                                            f"{max_mass:.0f} kg"
        elif broken:
            status, reason = "uncertain", f"the force balance does not hold on {100 * chosen.rejected_share[j]:.0f} % " \
                                          f"of its samples (an auxiliary load or PTO running, unflagged braking)"
        elif chosen.mass_std_kg[j] > settings.max_relative_uncertainty * mass:
            status, reason = "uncertain", f"statistical uncertainty {chosen.mass_std_kg[j]:.0f} kg over " \
                                          f"{100 * settings.max_relative_uncertainty:.0f} %"
        segment.update(mass_regressor=chosen.regressor, mass_joint_status=status, mass_joint_reason=reason,
                       **_aux_power(chosen, j, gain["gain"]))
        if status == "ok":
            segment["mass_kg"], segment["mass_uncertainty_kg"] = float(mass), float(sigma)
            columns["mass_kg"][start:end] = mass
        elif segment["status"] == "ok" and status == "no_excitation":
            # the LS of (9) only where the joint fit had too few samples to say anything; where
            # it found the segment uncertain, the LS (no wind, no torque offset, the datasheet
            # road load) is not more certain, it only ignores what the joint fit saw (harsh
            # urban: +25.6 % inside a stated 4.6 %). Its uncertainty gets the gain's term too, and
            # what the LS leaves out that the joint fit models (wind, c_r, c_d·A, offset, accessories)
            ls = segment["mass_ls_kg"] / gain["gain"]
            left_out = 0.0
            if speed is not None:
                part = slice(start, end)
                left_out = ls_unmodelled_kg(
                    regression.phi[part], regression.y[part], speed[part], regression.cos_angle[part],
                    segment["mass_ls_kg"], vehicle, settings, None if offset is None else offset[part],
                    None if aux is None else aux[part], None if aux_prior is None else aux_prior[j]) / gain["gain"]
            segment["mass_kg"] = ls
            segment["mass_uncertainty_kg"] = float(np.sqrt((segment["uncertainty_kg"] / gain["gain"]) ** 2
                                                           + (ls * gain["relative_std"]) ** 2
                                                           + np.nan_to_num(left_out) ** 2))
        else:
            segment["mass_kg"] = segment["mass_uncertainty_kg"] = None
    if chosen.aux_power_w is not None:
        held = (f"{100 * settings.parasitic_estimate_uncertainty:g} % of the accessories' power the engine reports "
                f"(SPN 2978, taken off the force)" if aux_prior is not None else "that prior")
        notes.append(f"an auxiliary power (compressor, fan, alternator) fitted per segment, >= 0 with a "
                     f"{settings.aux_power_sigma_w / 1000:g} kW prior; where the drive cannot tell it from the mass "
                     f"(aux_power_identified false) {held} is in the mass's uncertainty")
    if chosen.headless_samples is not None and chosen.headless_samples.any():
        fitted = ", ".join(f"{j} ({n})" for j, n in enumerate(chosen.headless_samples) if n)
        notes.append(f"segment(s) {fitted} fitted with samples without a GPS heading (an outage; too few with "
                     f"one): the head wind there is unknown, its drag is in the mass's uncertainty")
    if chosen.outliers:
        notes.append(f"{chosen.outliers} samples got weight 0 in the joint fit: their force balance is broken "
                     f"(auxiliary loads, unflagged braking)")
    road_load = {"regressor": chosen.regressor, "condition_number": chosen.condition,
                 "samples_zero_weight": chosen.outliers, "torque_gain": gain}
    for name in chosen.coefficients:
        scale = 1 / gain["gain"] if name == "drag_area_m2" else 1.0  # F_aero scales with the torque gain
        std = chosen.coefficient_std[name]
        road_load[name] = {"value": chosen.coefficients[name] * scale, "std": None if std is None else std * scale,
                           "identified": chosen.identified[name], "reason": chosen.reasons[name]}
    if gain["calibrated_from"] is None:
        notes.append(f"mass uncertainty includes {100 * gain_uncertainty:.1f} % for the engine torque report and "
                     f"driveline efficiency gain (give one weighed segment in mass.weighed_masses_kg to calibrate it)")
    else:
        notes.append(f"torque gain calibrated from segment(s) {gain['calibrated_from']}: {gain['gain']:.4f} "
                     f"± {100 * gain['relative_std']:.2f} %")
    for name, entry in road_load.items():
        if isinstance(entry, dict) and "identified" in entry and not entry["identified"]:
            notes.append(f"{name}: {entry['reason']}")
    return road_load, chosen
