"""The longitudinal force balance as a gradient measurement, for logs without an accelerometer.

Given the mass m, the engine torque, gear and wheel speed give what an accelerometer would
measure (paper (1)/(10)):

    a_virtual = (F_wheel - F_aero) / m - g c_r cos(alpha)  =  dv/dt + g sin(alpha)

on the samples the mass's data filter keeps (no brake, no shift, clutch closed; with traction,
and coasting and engine braking in gear where the torque report includes the engine's drag). It
enters the smoother through the accelerometer's channel, whose bias state takes up a constant
error (c_r, a torque offset) and, with masses from a first pass, a scale state per mass segment
the mass's error (`SCALE_STATE`); its noise and curvature are estimated from the data as for an
IMU without a barometer. The mass comes from a first pass (GPS altitude and DEM), or is given.
With a log that reports the engine's friction (J1939 SPN 514) the torque report's offset is found on
the samples where the truck brakes in gear and taken off, whether the mass is given or from a first
pass; with a first pass's masses the engine's drag also tightens the braking bound (`engine_drag`),
and what the bias state cannot hold of the wind and of the offset's remaining error is in the
sigma (`drag_sigma`).

Identifiability: a mass error dm/m scales the whole measurement, so it reads as a gradient error
of -(dm/m)(a + g sin(alpha) + g c_r) / g, which the bias takes up only where that sum is
constant. Within one drive the force balance alone cannot tell the mass from the gradient
(any m with its own gradient fits the torque); only the height sources over long baselines
(GPS altitude, the DEM, a barometer) and the acceleration pin the mass: the first pass's mass
and, in the second pass, the scale state, whose stated sigma says how well (on the accuracy
matrix too small: its truth inside ±2σ on 48-76 % of the segments, so it corrects the gradient
and is reported, not used as a mass). The mass stage fits the masses again on the second pass's
gradient (`MASS_REFIT`): the first pass's GPS-altitude gradient is too noisy a regressor for them.
The force balance is not run again with those (in town they made its gradient worse), and they are
not iterated: with the force balance carrying the gradient each refit returns mostly the mass put
in, and its own regressor noise drifts it low; their σ holds the scale state's.
A torque-report gain enters the same way as a mass error and needs a weighing.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from ..engine_torque import NET, driveline_torque_nm, knows_engine_drag, torque_report_form
from ..errors import UserError
from ..mass.joint import JointSettings
from ..road_load import G_MPS2, aero_force_n, wheel_force_from_torque_n, wheel_torque_from_engine_nm
from .drag_sigma import head_wind_sigma_mps2, unheld_drag_sigma_mps2, unknown_wind_drag_sigma_mps2
from .engine_drag import FRICTION_MAP_UNCERTAINTY, overrun_wheel_force_n, torque_report_offset
from .estimate import GradientResult, GradientSettings, estimate_gradient
from .sources import imu_excess_mps2


GIVEN_MASS_GAIN_UNCERTAINTY = 0.036
"""Relative 1-sigma of the force with a given mass: the torque report and driveline gain
(sqrt(3² + 2²) %, as `mass.joint.JointSettings`), which a weighing does not remove here."""
ROLLING_RESISTANCE_UNCERTAINTY = 0.15
"""Relative uncertainty of a vehicle file's c_r (datasheet width, as the joint mass's prior)."""


MOVING_SPEED_MPS = 1.0
"""Speed [m/s] above which the truck moves: the floor of the force balance with a first pass's
masses (`virtual_accelerometer_mps2`'s ``slow``)."""


def _force_filter(coasting: bool, slow: bool = False):
    """The mass's data filter without its excitation rules (a gradient measurement needs none),
    without its torque floor when ``coasting``, and with ``slow`` without its speed floor but for
    `MOVING_SPEED_MPS`."""
    from ..mass.regression import FilterSettings
    floor = -np.inf if coasting else FilterSettings.min_engine_torque_nm
    speed = MOVING_SPEED_MPS if slow else FilterSettings.min_speed_mps
    return FilterSettings(min_accel_mps2=-np.inf, min_regressor_mps2=-np.inf, min_engine_torque_nm=floor,
                          min_speed_mps=speed)


def virtual_accelerometer_mps2(frame: pd.DataFrame, vehicle, mass_kg: np.ndarray, coasting: bool = True,
                               slow: bool = False) -> np.ndarray:
    """a_virtual [m/s²] per sample (NaN where the data filter rejects the sample or the mass is
    unknown): what a longitudinal accelerometer would read, from the force balance, on every sample
    with no brake, no shift and the clutch closed. With ``coasting`` and a torque report that
    includes the engine's drag (`engine_torque.knows_engine_drag`) that is also where the truck coasts or
    engine-brakes in gear: there the force is small, so a mass error k moves the reading by only
    k (F_wheel - F_aero)/m (on the urban drives of the matrix half the distance the truck moves
    without braking had a torque under the mass filter's 200 Nm). With ``slow`` also below the
    mass filter's 5.5 m/s (the paper's rule for the mass regression's excitation, not a limit of
    the force balance: the ratio rule still drops a slipping clutch); on the matrix's urban typical
    drives its residual against the truth there was as small as above (0.00-0.05 ± 0.02 m/s²)."""
    from ..mass.regression import build_regression
    regression = build_regression(frame, vehicle, _force_filter(coasting and knows_engine_drag(frame), slow))
    rolling = G_MPS2 * vehicle.rolling_resistance_coefficient * regression.cos_angle
    with np.errstate(invalid="ignore", divide="ignore"):
        value = regression.y / np.asarray(mass_kg, dtype=float) - rolling
    return np.where(regression.usable & np.isfinite(value), value, np.nan)


def segment_masses_kg(frame: pd.DataFrame, vehicle) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample, the mass [kg] of its segment from `estimate_mass` on ``frame``'s gradient_pct,
    its 1-sigma [kg] and the segment's number (-1 outside every segment): the confident mass, or
    the joint fit's where it is only uncertain (its uncertainty then widens the gradient's); NaN
    where a segment has no plausible mass (`_with_unknown_masses`)."""
    from ..mass import estimate_mass
    result = estimate_mass(frame, vehicle)
    time_s = frame["time_s"].to_numpy(dtype=float)
    mass, sigma = np.full(len(frame), np.nan), np.full(len(frame), np.nan)
    number = np.full(len(frame), -1.0)
    for k, segment in enumerate(result.segments):
        inside = (time_s >= segment["start_s"]) & (time_s <= segment["end_s"])
        number[inside] = k
        value, std = segment.get("mass_kg"), segment.get("mass_uncertainty_kg")
        if value is None and segment.get("status") in ("ok", "uncertain") and segment.get("mass_ls_kg") is not None and \
                "force balance does not hold" not in segment.get("mass_joint_reason", ""):
            # the LS of (9) where the joint fit is only uncertain: `mass_kg` no longer reports
            # it (not confident), but here it is a better first guess than the joint value (on
            # the matrix's urban gps+can drives: 0.46 against 1.08 %-pt)
            # the LS's uncertainty has a fixed 0.1 %-pt gradient bias; the joint fit's has the
            # first pass's stated gradient sigma, which is what the force balance inherits
            regressor = segment.get("mass_regressor", "gradient")
            value = segment["mass_ls_kg"]
            std = np.nanmax([np.nan if v is None else v for v in (
                segment.get("uncertainty_kg"), segment.get(f"mass_{regressor}_uncertainty_kg"), np.nan)])
        elif value is None and segment.get("mass_joint_status") == "uncertain":
            regressor = segment.get("mass_regressor", "gradient")
            value, std = segment.get(f"mass_{regressor}_kg"), segment.get(f"mass_{regressor}_uncertainty_kg")
        if value is not None and np.isfinite(value):
            mass[inside] = value
            sigma[inside] = std if std is not None else np.nan
    return mass, sigma, number


UNKNOWN_MASS_RELATIVE_SIGMA = 0.4
"""Relative 1-sigma of the mass a segment without one of its own is given (`_with_unknown_masses`):
an empty and a full truck differ by a factor of two or more."""


def _with_unknown_masses(mass_kg: np.ndarray, sigma_kg: np.ndarray):
    """Segments without a mass of their own (too few samples for the mass's filter) take the drive's
    median mass with `UNKNOWN_MASS_RELATIVE_SIGMA`: their coasting samples barely need one, and the
    mass's share in the noise (`scale_variance_m2ps4`) weighs their pulling samples by that sigma.
    Without, the force balance measured nothing there (urban ideal seed 1: 0.51 %-pt, 0.10 with)."""
    known = np.isfinite(mass_kg)
    if not known.any() or known.all():
        return mass_kg, sigma_kg
    median = float(np.median(mass_kg[known]))
    return (np.where(known, mass_kg, median),
            np.where(known, sigma_kg, UNKNOWN_MASS_RELATIVE_SIGMA * median))


def estimate_gradient_force_balance(frame: pd.DataFrame, dem, vehicle, settings: GradientSettings = GradientSettings(),
                                    mass_kg: float | np.ndarray | None = None) -> GradientResult:
    """`estimate_gradient` with the force balance as the accelerometer of a log that has none.
    ``mass_kg``: the truck's mass [kg] when it is known (weighed; one value or one per sample),
    which also makes the bias known (to the rolling resistance's 15 %) so that the force balance
    is a height source on its own; otherwise each segment's mass from a first pass without it.
    Raises `UserError` as `estimate_gradient` does, or when the log has an accelerometer."""
    if "accel_x_mps2" in frame.columns and frame["accel_x_mps2"].notna().any():
        raise UserError("gradient: the log has an accelerometer (accel_x_mps2); the force balance is for logs without")
    first_grid_std = None
    # both passes: the first pass's gradient gives the masses
    settings = replace(settings, smoother=replace(settings.smoother, gps_multipath_share=True))
    try:
        first_pass = estimate_gradient(frame, dem, settings)
        samples = first_pass.samples
        if settings.gradient_method == "smoother":
            first_grid_std = first_pass.grid["gradient_smooth_std_pct"].to_numpy()
        gradient = samples["gradient_pct"]
        # the first pass's stated sigma goes into its masses' uncertainty (`mass._with_gradient_std`)
        gradient_std = (samples["gradient_smooth_std_pct"] if settings.gradient_method == "smoother"
                        else np.full(len(frame), np.nan))
    except UserError:
        if mass_kg is None:
            raise
        gradient, gradient_std = np.zeros(len(frame)), np.full(len(frame), np.nan)
    first = frame.assign(gradient_pct=np.nan_to_num(gradient), gradient_std_pct=np.asarray(gradient_std, dtype=float))
    scaled, offset, drag = False, None, None
    if knows_engine_drag(frame):
        # an indicated report reads 0 % in a fuel cut whatever its offset: only a net one shows it;
        # it needs no mass, so a given one (`can-only`) is corrected by it too
        offset = torque_report_offset(frame, vehicle) if torque_report_form(frame) == NET else None
        drag = overrun_wheel_force_n(frame, vehicle) if mass_kg is None else None
    forced = first if offset is None else first.assign(engine_torque_nm=first["engine_torque_nm"] - offset.offset_nm)
    if mass_kg is None:
        mass, mass_sigma, segment = segment_masses_kg(first, vehicle)
        mass, mass_sigma = _with_unknown_masses(mass, mass_sigma)
        relative = mass_sigma / mass
        source = "each segment's mass from a first pass without it"
        scaled = SCALE_STATE
    else:
        mass = np.broadcast_to(np.asarray(mass_kg, dtype=float), (len(frame),))
        relative = np.full(len(frame), GIVEN_MASS_GAIN_UNCERTAINTY)
        source = f"the given mass {np.nanmedian(mass):.0f} kg"
        bias_sigma = G_MPS2 * vehicle.rolling_resistance_coefficient * ROLLING_RESISTANCE_UNCERTAINTY
        settings = replace(settings, smoother=replace(settings.smoother, imu_bias_prior_sigma_mps2=bias_sigma))
    settings = replace(settings, smoother=replace(settings.smoother, force_balance=True))
    log = frame
    frame, virtual, gaps, result = _force_balance_pass(log, forced, dem, vehicle, settings, mass, relative,
                                                       segment if scaled else None, mass_kg is None)
    mass_gradient, mass_gradient_std = gradient, gradient_std
    if mass_kg is None and MASS_REFIT:
        # the masses are fitted again on this pass's gradient (where the scale state let the height
        # sources correct the first pass's masses); the gradient itself stays on the first pass's
        mass_gradient = np.asarray(result.samples["gradient_pct"], dtype=float).copy()
        mass_gradient_std = np.asarray(result.samples["gradient_smooth_std_pct"], dtype=float).copy() \
            if settings.gradient_method == "smoother" else np.full(len(log), np.nan)
    measured = virtual
    no_height_source = not _has_height_source(result)
    # only with no height source: there the sigma comes from the road's spread away from the
    # measured bins (`_widen_in_gaps`); with GPS altitude the bound, taken as a measurement, made
    # the smoother's sigma too small (urban gps+can: 97 -> 79 % inside ±2σ)
    if BRAKING_BOUND and no_height_source:
        bounded = _braking_bound(result, frame, virtual, vehicle, mass)
        if bounded is not None:
            virtual = bounded
            if gaps is not None:
                kept = imu_excess_mps2(np.where(gaps.added, np.nan, bounded), frame["accel_mps2"].to_numpy(dtype=float),
                                       frame["time_s"].to_numpy(dtype=float))
                frame = frame.assign(accel_x_excess_mps2=np.where(gaps.added, gaps.sine_mps2, kept))
            result = estimate_gradient(frame.assign(accel_x_mps2=virtual), dem, settings)
            result.notes.append(f"the force balance's braking bound (the brakes only take force away) held the "
                                f"gradient down on {np.sum(np.isfinite(virtual) & ~np.isfinite(measured))} samples "
                                f"where it was above what braking allows")
    if not no_height_source:
        window_bound = _window_braking_bound(forced, vehicle, mass) if mass_kg is None and FORCE_GAPS else None
        _hold_under_braking_bound(result, frame, vehicle, mass, relative, settings.spacing_m, drag, window_bound)
    if gaps is not None and gaps.added.any():
        result.notes.append(f"the force balance over windows of known force (across gear shifts: the clutch open, no "
                            f"engine force) on {int(gaps.added.sum())} samples the data filter's 1-s window could not take")
    if offset is not None:
        result.notes.append(f"torque report's offset {offset.offset_nm:+.0f} ± {offset.sigma_nm:.0f} Nm (what it reads above "
                            f"minus the engine's friction, J1939 SPN 514, on {offset.samples} samples braking in gear in "
                            f"{offset.applications} brake applications) taken off the force balance")
    if scaled:
        _report_scale(result, frame, mass)
        if mass_kg is None and MASS_REFIT:
            result.samples["gradient_mass_scale_rel_std"] = _scale_std_per_sample(result, frame)
    _add_mass_uncertainty(result, frame, virtual, relative, vehicle, settings.spacing_m,
                          None if mass_kg is None else mass)
    if no_height_source:
        _add_road_load_uncertainty(result, frame, virtual, vehicle, mass, settings.spacing_m,
                                   None if offset is None else offset.sigma_nm)
        # the gaps are where the truck does not pull: a coasting sample's force is a small sum of
        # drags (engine, air, rolling) whose errors, the torque report's offset (2-6 times c_r's
        # share in acceleration on the matrix) and the wind, the given mass's bias prior (c_r
        # only) does not hold; with coasting counted as measured, can-only harsh's least drive
        # had 50 % inside ±2σ, 60 % before
        pulling = virtual_accelerometer_mps2(first, vehicle, mass, coasting=False)
        _widen_in_gaps(result, frame, pulling, settings.spacing_m)
    else:
        _height_sources_sigma_in_gaps(result, frame, measured, first_grid_std, settings.spacing_m)
        if mass_kg is None:
            offset_sigma = (TORQUE_OFFSET_UNCERTAINTY * _reference_torque_nm(frame, vehicle) if offset is None
                            else offset.sigma_nm)
            _widen_where_measured(result, frame, unheld_drag_sigma_mps2(frame, vehicle, mass, virtual, offset_sigma),
                                  settings.spacing_m)
    if mass_kg is None:
        result.samples["gradient_mass_pct"] = np.asarray(mass_gradient, dtype=float)
        result.samples["gradient_mass_std_pct"] = np.asarray(mass_gradient_std, dtype=float)
        # the gradient the masses were fitted on (the second pass's with `MASS_REFIT`), not its
        # posterior: its errors hold the force balance's, with the mass put in, which no posterior
        # of zero-mean errors states; its σ as one error stays
    result.notes = [n for n in result.notes if "IMU carries the gradient" not in n]
    result.notes.append(f"no IMU: the force balance (engine torque, gears, wheel speed, {source}) stands in for "
                        f"the accelerometer on {100 * np.isfinite(virtual).mean():.0f} % of the samples; a mass or "
                        f"torque-gain error of k % reads as k % of (a + g sin alpha) in the gradient")
    result.smoother["force_balance"] = True
    if "gradient_imu_pct" in result.grid:  # (7) of the stand-in, not of an IMU
        result.grid = result.grid.rename(columns={"gradient_imu_pct": "gradient_force_balance_pct"})
        result.samples["gradient_force_balance_pct"] = result.samples.pop("gradient_imu_pct")
    return result


def _force_balance_pass(frame, forced, dem, vehicle, settings, mass, relative, segment, first_pass_masses):
    """One smoother pass with the force balance of ``mass`` [kg per sample] (relative 1-sigma
    ``relative``) as the accelerometer, a scale state per ``segment`` (None: no state). Returns the
    log with the smoother's force-balance columns, a_virtual, the force gaps and the result."""
    virtual = virtual_accelerometer_mps2(forced, vehicle, mass, slow=first_pass_masses)
    if not np.isfinite(virtual).any():
        raise UserError("gradient: no sample passes the force balance's data filter (traction, no brake, no shift)")
    accel = frame["accel_mps2"].to_numpy(dtype=float)
    extra_var, gaps = np.zeros(len(frame)), None
    if FORCE_GAPS:
        # with a given mass above the mass filter's speed floor, as its data filter (`slow`)
        gaps = _with_force_gaps(forced, vehicle, mass, virtual, accel,
                                MOVING_SPEED_MPS if first_pass_masses else _force_filter(True).min_speed_mps)
        virtual, accel, extra_var = gaps.virtual_mps2, gaps.accel_mps2, gaps.variance_m2ps4
        frame = frame.assign(accel_x_excess_mps2=gaps.excess_mps2)
    if segment is not None:
        regressor = accel + G_MPS2 * vehicle.rolling_resistance_coefficient
        frame = frame.assign(accel_x_scale_regressor_mps2=regressor,
                             accel_x_scale_segment=segment, accel_x_scale_sigma=np.log1p(relative))
    # the mass's share in the noise stays beside the scale state: the state is one constant per
    # segment, the force balance's scale varies within it (the driveline's efficiency by gear, the
    # auxiliaries); the state alone left 62 % of the bins inside ±2σ on the least typical drive
    frame = frame.assign(accel_x_scale_var_m2ps4=scale_variance_m2ps4(virtual, relative, vehicle) + extra_var)
    return frame, virtual, gaps, estimate_gradient(frame.assign(accel_x_mps2=virtual), dem, settings)


MASS_REFIT = True
"""With a first pass's masses: the masses the mass stage reports are fitted on the second pass's
gradient (`gradient_mass_pct`), not the first pass's GPS-altitude one (errors-in-variables: its
masses low, and most not confident; the second pass's is 2-4 times better). The force balance is
not run again with them: in town, where the height sources cannot pin the scale state, the refitted
masses (8-50 % off) made a third pass's gradient worse (``docs/estimation.md``); so the gradient is
the second pass's, on the first pass's masses, with this on or off."""


FORCE_GAPS = True
"""The force balance also where its 1-s window cannot span: across gear shifts with the clutch open
(with a given mass above the mass filter's speed floor, as its data filter), and with a first
pass's masses as the braking bound's upper limit across short brake applications (`force_gaps`)."""


FORCE_GAPS_MARGIN_S = 1.0
"""The force gaps' windows keep this far [s] from a brake application and from a gear change with
no neutral reported, as the data filter does (its 0.5 s margin and half its 1-s window): the brake
switch is read once per sample, and on the matrix's urban drives the brake acted unseen between
readings near its applications (with the truth's mass, the windows' g sin(alpha) read +0.10 to
+0.22 m/s² high one or two samples from a brake reading, +0.05 to +0.08 three, +0.03 four or five)."""


@dataclass
class ForceGaps:
    """The force balance with its windows of known force (`_with_force_gaps`), per sample."""
    virtual_mps2: np.ndarray
    """a + g sin(alpha): the data filter's, or where it left none, a window's."""
    accel_mps2: np.ndarray
    """The acceleration each value of ``virtual_mps2`` pairs with."""
    variance_m2ps4: np.ndarray
    """The added samples' variance, 0 elsewhere."""
    excess_mps2: np.ndarray
    """a_x - dv/dt for the smoother (`sources.imu_excess_mps2` of the filter's samples)."""
    added: np.ndarray
    """Where a window stands in for the data filter."""
    sine_mps2: np.ndarray
    """Every window's g sin(alpha) (NaN where none)."""


def _with_force_gaps(frame, vehicle, mass, virtual, accel, moving_mps) -> ForceGaps:
    """The force balance with `force_gaps.windowed_force_balance` where the data filter left no
    sample; where the filter kept one, all is as before. Windows lie above ``moving_mps``."""
    from ..mass.regression import FilterSettings
    from .force_gaps import windowed_force_balance
    time_s = frame["time_s"].to_numpy(dtype=float)
    kept = imu_excess_mps2(virtual, accel, time_s)
    sine, window_accel, variance = windowed_force_balance(
        frame, vehicle, mass, moving_mps, FilterSettings.min_engine_torque_nm, FORCE_GAPS_MARGIN_S)
    added = ~np.isfinite(kept) & np.isfinite(sine) & np.isfinite(variance)
    return ForceGaps(np.where(added, sine + window_accel, virtual), np.where(added, window_accel, accel),
                     np.where(added, variance, 0.0), np.where(added, sine, kept), added, sine)


SCALE_STATE = True
"""With masses from a first pass, the force balance's scale is a state of the smoother per mass
segment (`kalman.SCALE`): with a mass m for a true m_true it reads m_true/m times the true
a + g sin(alpha) + g c_r, much where the truck pulls, little where it coasts, and as a constant
offset the bias state took the mean of that and the engine-braked descents read too steep. The
scale multiplies the smoother's own gradient and dv/dt, not the measured force (which holds the
road's short hills that the smoothed gradient does not, and read as a scale: urban masses +20 to
+70 % off), and is a log, so no estimate can flip the force's sign. With a given mass it is off."""


def _report_scale(result: GradientResult, frame, mass):
    """Per segment the scale state's estimate and 1-sigma (how well the force balance's
    pulling/coasting contrast and the height sources pin the first pass's mass), in a note and
    in ``smoother["force_balance_scale"]``: the mass it implies is m (1 + k)."""
    grid = result.grid
    if "force_balance_log_scale" not in grid or "accel_x_scale_segment" not in frame:
        return
    distance = frame["distance_m"].to_numpy(dtype=float)
    segment = frame["accel_x_scale_segment"].to_numpy(dtype=float)
    time_s = frame["time_s"].to_numpy(dtype=float)
    mass = np.asarray(mass, dtype=float)
    s_grid = grid["distance_m"].to_numpy()
    rows = []
    for number in np.unique(segment[segment >= 0]):
        inside = (segment == number) & np.isfinite(distance)
        if not inside.any():
            continue
        at = int(np.clip(np.searchsorted(s_grid, np.median(distance[inside])), 0, len(s_grid) - 1))
        log_scale = float(grid["force_balance_log_scale"].iloc[at])
        k, std = float(np.expm1(log_scale)), float(np.exp(log_scale) * grid["force_balance_log_scale_std"].iloc[at])
        used = float(np.nanmedian(mass[inside]))
        rows.append({"segment": int(number), "start_s": float(time_s[inside].min()), "end_s": float(time_s[inside].max()),
                     "scale": k, "scale_std": std, "mass_kg": used,
                     "mass_implied_kg": used * (1 + k)})
    result.smoother["force_balance_scale"] = rows
    if rows:
        result.notes.append("force balance scale per segment (true mass / first pass's mass - 1, from the "
                            "acceleration and the height sources; a correction of the gradient, not a mass: its statistical "
                            "sigma understates the error): " + ", ".join(
                                f"{r['segment']}: {100 * r['scale']:+.1f} ± {100 * r['scale_std']:.1f} %" for r in rows))


def _scale_std_per_sample(result: GradientResult, frame) -> np.ndarray:
    """Per sample its segment's scale state's 1-sigma [-] (`_report_scale`), NaN outside: how well
    the second pass pinned the first pass's mass that its gradient, the refit's regressor
    (`MASS_REFIT`), carries; the rest of that mass's error is in the refit's, each segment's own."""
    time_s = frame["time_s"].to_numpy(dtype=float)
    std = np.full(len(frame), np.nan)
    for row in result.smoother.get("force_balance_scale", []):
        std[(time_s >= row["start_s"]) & (time_s <= row["end_s"])] = row["scale_std"]
    return std


def scale_variance_m2ps4(virtual, relative, vehicle) -> np.ndarray:
    """Variance [m²/s⁴] per sample that a relative mass (or torque-gain) error of 1-sigma
    ``relative`` gives the force balance: (relative (a_virtual + g c_r))², the error k
    (F_wheel - F_aero)/m. Large where the truck pulls hard, near zero where it coasts: in the
    smoother's noise it makes the gradient lean on the coasting samples and the height sources
    where the mass is uncertain, on the pulling samples where it is known."""
    return (np.nan_to_num(relative) * (virtual + G_MPS2 * vehicle.rolling_resistance_coefficient)) ** 2


def _has_height_source(result: GradientResult) -> bool:
    """Whether a barometer, the map or GPS altitude measured a height."""
    grid = result.grid
    return any(column in grid for column in ("gradient_baro_pct", "gradient_map_pct")) or \
        bool((grid.get("weight_smooth_gps", pd.Series([0.0])) > 0).any())


BRAKING_BOUND = True
"""Hold the force balance's gradient under what braking allows (`_braking_bound`)."""


def _braking_bound(result, frame, virtual, vehicle, mass):
    """The force balance where the truck brakes: the brakes only take force away, so
    dv/dt + g sin(alpha) <= (F_engine - F_aero)/m - g c_r with F_engine the engine's pull (>= 0). Where the smoothed gradient breaks that
    bound the bound itself becomes the measurement (the smoother's estimate projected onto what the
    physics allows; a truck brakes on descents, which the random walk across the gap does not know).
    Returns the force balance with those samples added, or None where none breaks it."""
    if not {"brake_switch", "engine_torque_nm", "accel_mps2", "engine_speed_rpm"} <= set(frame.columns):
        return None
    brake, accel, rpm, speed = (frame[c].to_numpy(dtype=float) for c in (
        "brake_switch", "accel_mps2", "engine_speed_rpm", "speed_mps"))
    torque = driveline_torque_nm(frame)
    braking = (np.nan_to_num(brake) > 0.5) & (speed > 3.0) & ~np.isfinite(virtual)
    with np.errstate(invalid="ignore", divide="ignore"):
        pushing = wheel_force_from_torque_n(wheel_torque_from_engine_nm(
            np.clip(torque, 0, None), rpm, speed, vehicle.wheel_radius_m, vehicle.driveline_efficiency),
            vehicle.wheel_radius_m)
        bound = (np.nan_to_num(pushing) - aero_force_n(speed, vehicle.drag_coefficient, vehicle.frontal_area_m2)) \
            / np.asarray(mass, dtype=float) - G_MPS2 * vehicle.rolling_resistance_coefficient
    gradient = result.samples["gradient_smooth_pct"] / 100.0
    bias = result.samples.get("imu_bias_mps2", np.zeros(len(frame)))
    estimate = accel + G_MPS2 * gradient / np.sqrt(1 + gradient ** 2) + np.nan_to_num(bias)
    broken = braking & np.isfinite(bound) & (estimate > bound)
    if broken.sum() < 10:
        return None
    out = np.array(virtual, dtype=float)
    out[broken] = bound[broken]
    return out


def _gaps(grid, frame, virtual, spacing_m):
    """(w, measured, length) where ``virtual`` measured on at least 50 grid points and not on all:
    w = exp(-2 d / L) per grid point, d the distance to the nearest measured grid point and L
    [bins] the correlation length of the smoothed gradient where it measured; None otherwise."""
    from scipy.ndimage import distance_transform_edt

    from . import grid as distance_grid
    from .smoother import _correlation_length_bins
    if "distance_m" not in frame:
        return None
    distance = frame["distance_m"].to_numpy(dtype=float)
    measured = np.zeros(len(grid), bool)
    ok = np.isfinite(distance) & np.isfinite(virtual)
    index = distance_grid.grid_index(distance[ok], spacing_m)
    measured[index[(index >= 0) & (index < len(grid))]] = True
    if measured.sum() < 50 or measured.all():
        return None
    gradient = grid["gradient_smooth_pct"].to_numpy()
    length = _correlation_length_bins(np.where(measured, gradient, np.nan), max_lag=len(grid) // 2)
    if not np.isfinite(length) or length <= 0:
        return None
    return np.exp(-2 * distance_transform_edt(~measured) / length), measured, length


def _set_grid(result: GradientResult, frame, **columns):
    """Grid columns replaced, and their per-sample values interpolated again at the samples' distance."""
    distance = frame["distance_m"].to_numpy(dtype=float)
    s_grid = result.grid["distance_m"].to_numpy()
    for name, values in columns.items():
        result.grid[name] = values
        result.samples[name] = np.interp(distance, s_grid, np.asarray(values, dtype=float), left=np.nan, right=np.nan)


BRAKE_HELD_S = 1.0
"""The braking bound takes a sample only where the brake is on this long [s] before and after it:
the acceleration from wheel speed is smoothed and lags the brake's onset (measured: -0.2 m/s² read
for a true -0.6 in the first half second)."""


def _window_braking_bound(frame, vehicle, mass):
    """Where the brake may act within the 1-s windows of known engine force (`force_gaps`, brakes
    counted as an unknown loss): (the upper bound of g sin(alpha) [m/s²], its variance [m²/s⁴],
    the windows' mean (F_wheel - F_aero)/m [m/s²]) per sample, NaN elsewhere."""
    from ..mass.regression import FilterSettings
    from .force_gaps import windowed_force_balance
    args = (frame, vehicle, mass, MOVING_SPEED_MPS, FilterSettings.min_engine_torque_nm, FORCE_GAPS_MARGIN_S)
    measured, _, _ = windowed_force_balance(*args)
    bound, accel, variance = windowed_force_balance(*args, brakes=False)
    bound = np.where(np.isfinite(measured), np.nan, bound)
    rolling = G_MPS2 * vehicle.rolling_resistance_coefficient
    return bound, variance, bound + rolling + accel


def _hold_under_braking_bound(result: GradientResult, frame, vehicle, mass, relative, spacing_m, drag_n=None,
                              window_bound=None):
    """With height sources, the gradient held under what braking allows, as a one-sided bound: where
    the truck brakes and the engine does not pull (torque <= 0) the wheels get no traction, so
    a + g sin(alpha) <= -F_aero/m - g c_r, to within a margin of two sigma of the bound's own error
    (the head wind's drag with a 5 m/s prior, c_r's 15 %, the mass's share of F_aero/m). With
    ``drag_n`` (`engine_drag.overrun_wheel_force_n`: the engine motored in gear, its friction from
    SPN 514) the wheels also get the engine's drag, F_aero - F_drag in place of F_aero, and the
    friction map's 10 % joins the margin. With ``window_bound`` (`_window_braking_bound`) also where
    the brake acts in short applications (the brake switch on for single readings, the windows of
    known engine force between them too short for the data filter): over a 1-s window of known
    engine force, g sin(alpha) is at most its force balance without the brakes, to within two sigma
    of the wheel speed's noise over the window, the head wind and c_r as above, and the mass's share
    of the window's force. Per grid
    point the gradient is clipped to the mean bound of its braking samples; the heights are
    integrated again, the sigma is kept (a clip onto a bound the road satisfies only moves the
    estimate towards it). Across braking gaps the height sources (urban GPS altitude and a DEM
    with buildings) had the gradient positive while the truck braked at constant speed. Taken as
    a measurement in the smoother instead (the can-only way) the bound shifted the force
    balance's bias and the gradient elsewhere (urban gps+can: 97 -> 79 % inside ±2σ)."""
    from scipy.ndimage import binary_erosion

    from . import grid as distance_grid
    from .estimate import _integrate, _sample_rate_hz
    if not {"brake_switch", "engine_torque_nm", "accel_mps2", "distance_m"} <= set(frame.columns):
        return
    brake, accel, speed, distance, time_s = (frame[c].to_numpy(dtype=float) for c in (
        "brake_switch", "accel_mps2", "speed_mps", "distance_m", "time_s"))
    torque = driveline_torque_nm(frame)
    braking = (np.nan_to_num(brake) > 0.5) & (np.nan_to_num(torque, nan=1.0) <= 0) & (speed > 3.0)
    held = max(1, int(round(BRAKE_HELD_S * _sample_rate_hz(time_s))))
    braking = binary_erosion(braking, structure=np.ones(2 * held + 1, bool))
    mass = np.asarray(mass, dtype=float)
    engine = np.zeros(len(frame)) if drag_n is None else np.nan_to_num(np.asarray(drag_n, dtype=float))
    with np.errstate(invalid="ignore", divide="ignore"):
        aero = (aero_force_n(speed, vehicle.drag_coefficient, vehicle.frontal_area_m2) - engine) / mass
        wind = head_wind_sigma_mps2(speed, vehicle, mass)
        rolling = G_MPS2 * vehicle.rolling_resistance_coefficient
        margin = 2 * np.sqrt(wind ** 2 + (rolling * ROLLING_RESISTANCE_UNCERTAINTY) ** 2
                             + (aero * np.nan_to_num(relative)) ** 2 + (FRICTION_MAP_UNCERTAINTY * engine / mass) ** 2)
        sine = (-aero - rolling + margin - accel) / G_MPS2
        if window_bound is not None:
            bound, variance, net = (np.asarray(x, dtype=float) for x in window_bound)
            window_margin = 2 * np.sqrt(wind ** 2 + (rolling * ROLLING_RESISTANCE_UNCERTAINTY) ** 2
                                        + (net * np.nan_to_num(relative)) ** 2 + variance)
            windowed = ~braking & np.isfinite(bound)
            sine = np.where(windowed, (bound + window_margin) / G_MPS2, sine)
            braking = braking | windowed
    grid = result.grid
    index = np.where(np.isfinite(distance), distance_grid.grid_index(distance, spacing_m), -1)
    limit = distance_grid.bin_mean(index, np.where(braking, sine, np.nan), len(grid))
    limit_pct = 100 * np.tan(np.arcsin(np.clip(limit, -1, 1)))
    gradient = grid["gradient_smooth_pct"].to_numpy()
    above = np.isfinite(limit_pct) & (gradient > limit_pct)
    if not above.any():
        return
    gradient = np.where(above, limit_pct, gradient)
    height = _integrate(gradient / 100, spacing_m)
    height = height + np.mean(grid["height_smooth_m"].to_numpy() - height)
    columns = {"gradient_smooth_pct": gradient, "height_smooth_m": height}
    if result.smoother.get("method") == "smoother":
        columns.update(gradient_pct=gradient, height_m=height)
    _set_grid(result, frame, **columns)
    result.notes.append(f"braking bound: the gradient held under what braking allows on {above.sum()} grid points "
                        f"({100 * above.mean():.0f} % of the distance)")


def _widen_in_gaps(result: GradientResult, frame, virtual, spacing_m):
    """With no height source, where the truck does not pull (braking downhill, coasting: the
    force balance measures nothing or only small drags) the smoother's random walk extrapolates
    the gradient with a sigma that grows far slower than a road changes (matrix `can-only`
    typical: 75-79 % inside ±2σ). There the sigma returns to what the road is known to do: a
    stationary (Gauss-Markov) gradient with the RMS and the correlation length of the smoothed
    gradient where ``virtual`` (the force balance where the truck pulls) measured,
    sigma² = sigma_edge² w + rms² (1 - w), w = exp(-2 d / L), d the distance to the nearest
    measured grid point."""
    gaps = _gaps(result.grid, frame, virtual, spacing_m)
    if gaps is None:
        return
    w, measured, length = gaps
    gradient = result.grid["gradient_smooth_pct"].to_numpy()
    rms = float(np.sqrt(np.mean(gradient[measured] ** 2)))
    std = result.grid["gradient_smooth_std_pct"].to_numpy()
    _set_grid(result, frame, gradient_smooth_std_pct=np.sqrt(std ** 2 * w + np.maximum(rms ** 2, std ** 2) * (1 - w)))
    result.notes.append(f"no height source: where the force balance measures nothing ({100 * (1 - measured.mean()):.0f} % "
                        f"of the distance) the gradient's sigma returns to the road's own spread ({rms:.1f} %-pt "
                        f"over {length * spacing_m:.0f} m)")


def _height_sources_sigma_in_gaps(result: GradientResult, frame, virtual, first_std_pct, spacing_m):
    """With height sources, where the force balance measures nothing (braking, shifting, a segment
    without a plausible mass, a GPS outage) the gradient is the height sources' with the road
    curvature the force balance chose where it measured: a random walk fitted over 10 m bins,
    stiffer than a road is over hundreds of metres (the matrix's roads: the gradient's mean square
    change per metre is 14-18 times larger over 200 m than over 10 m), so its sigma there was too
    small (urban ideal drive: 86 % inside ±2σ). There the sigma returns, away from the measured bins,
    to at least the larger of the first pass's (the height sources alone, their curvature chosen by
    GPS altitude's innovations) and the road's own spread (the RMS of the smoothed gradient where the
    force balance measured, as with no height source at all, `_widen_in_gaps`):
    sigma² = sigma² w + max(sigma_first², rms², sigma²) (1 - w), w as in `_widen_in_gaps`. The
    first pass's sigma alone was too small in the gaps of the urban drives (matrix `typical` and
    `harsh`, traced with the truth: rms(error/sigma) 1.3-1.75, 71-91 % inside ±2σ): within a gap of
    a few hundred metres GPS altitude (metres of error) and the map (metres, correlated over
    hundreds of metres) tell the gradient no better than the road's spread, and GPS altitude's
    innovations choose a curvature stiffer than an urban road; the gaps are also where the truck
    brakes, on the steepest descents (urban `harsh` seed 2: a braked descent in a GPS outage 4.5
    %-pt off with a stated 1.3)."""
    gaps = _gaps(result.grid, frame, virtual, spacing_m)
    if gaps is None or first_std_pct is None:
        return
    w, measured, length = gaps
    gradient = result.grid["gradient_smooth_pct"].to_numpy()
    rms = float(np.sqrt(np.mean(gradient[measured] ** 2)))
    std = result.grid["gradient_smooth_std_pct"].to_numpy()
    first = np.nan_to_num(np.asarray(first_std_pct, dtype=float), nan=0.0)
    floor = np.maximum(np.maximum(first ** 2, rms ** 2), std ** 2)
    _set_grid(result, frame, gradient_smooth_std_pct=np.sqrt(std ** 2 * w + floor * (1 - w)))
    result.notes.append(f"where the force balance measures nothing ({100 * (1 - measured.mean()):.0f} % of the distance) "
                        f"the gradient's sigma returns to the larger of the height sources' and the road's own spread "
                        f"({rms:.1f} %-pt over {length * spacing_m:.0f} m)")


def scale_error_mps2(frame, virtual, relative, vehicle, mass_kg=None) -> np.ndarray:
    """1-sigma [m/s²] per sample of the force balance's error from a relative error ``relative`` of
    what scales it (NaN where ``virtual`` does not measure). A first pass's mass error k scales what
    the force balance divides by the mass, F_wheel - F_aero: k (a + g sin alpha + g c_r). With the
    mass given (``mass_kg``), k is the torque report's and the driveline's gain, which scales the
    wheel force alone: k F_wheel / m = k (a + g sin alpha + g c_r + F_aero / m), the air drag the
    engine pulls against included (at 20 m/s on a 12.6 t rigid truck 1.5 times g c_r)."""
    specific = np.asarray(virtual, dtype=float) + G_MPS2 * vehicle.rolling_resistance_coefficient
    if mass_kg is not None:
        speed = frame["speed_mps"].to_numpy(dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            specific = specific + aero_force_n(speed, vehicle.drag_coefficient, vehicle.frontal_area_m2) / mass_kg
    return np.abs(specific) * np.nan_to_num(relative)


def _add_mass_uncertainty(result: GradientResult, frame, virtual, relative, vehicle, spacing_m, mass_kg=None):
    """Widen the gradient's sigma by what the mass's (or, with ``mass_kg`` given, the torque gain's)
    relative error does to the force balance where it carries the gradient (`scale_error_mps2`), a
    systematic error over a segment that the smoother, taking the force balance as an unbiased
    accelerometer, cannot see."""
    _widen_where_measured(result, frame, scale_error_mps2(frame, virtual, relative, vehicle, mass_kg), spacing_m)


def _widen_where_measured(result: GradientResult, frame, specific_mps2, spacing_m):
    """The gradient's sigma widened, in quadrature, by a systematic error of the force balance
    ``specific_mps2`` [m/s², per sample, NaN where it does not measure] over g, in the share of each
    grid point that the force balance carries (its weight in the smoother)."""
    from . import grid as distance_grid
    distance = frame["distance_m"].to_numpy(dtype=float) if "distance_m" in frame else None
    grid = result.grid
    if distance is None or "weight_smooth_imu" not in grid:
        return
    index = np.where(np.isfinite(distance), distance_grid.grid_index(distance, spacing_m), -1)
    per_bin = distance_grid.bin_mean(index, specific_mps2, len(grid))
    s_grid = grid["distance_m"].to_numpy()
    ok = np.isfinite(per_bin)
    if not ok.any():
        return
    filled = np.interp(s_grid, s_grid[ok], per_bin[ok])
    extra_pct = 100 * filled / G_MPS2 * grid["weight_smooth_imu"].to_numpy()
    std = np.hypot(grid["gradient_smooth_std_pct"].to_numpy(), extra_pct)
    _set_grid(result, frame, gradient_smooth_std_pct=std)


TORQUE_OFFSET_UNCERTAINTY = JointSettings.torque_offset_uncertainty
"""1-sigma of the torque report's offset as a share of the reference torque: the mass fit's prior."""


def _reference_torque_nm(frame, vehicle) -> float:
    """The engine's reference torque [Nm]: the log's (EC1), else the vehicle file's, else NaN."""
    if "engine_reference_torque_nm" in frame and frame["engine_reference_torque_nm"].notna().any():
        return float(frame["engine_reference_torque_nm"].median())
    return float(getattr(vehicle, "engine_reference_torque_nm", None) or np.nan)


def road_load_sigma_mps2(frame, vehicle, mass_kg, offset_sigma_nm: float | None = None) -> np.ndarray:
    """1-sigma [m/s²] per sample of what the force balance with a given mass cannot know: the drag
    of a wind of unknown direction (`drag_sigma.unknown_wind_drag_sigma_mps2`) and the torque report's offset
    (``offset_sigma_nm``: its 1-sigma [Nm] where SPN 514 showed it, `engine_drag.torque_report_offset`;
    None: `TORQUE_OFFSET_UNCERTAINTY` of the reference torque), through the driveline's ratio, in
    quadrature. The rolling resistance's 15 % is in the bias prior; a constant bias is all the
    given mass's prior holds, while the wind's and the offset's share change with speed and gear."""
    speed = frame["speed_mps"].to_numpy(dtype=float)
    mass = np.asarray(mass_kg, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        wind = unknown_wind_drag_sigma_mps2(speed, vehicle, mass)
        offset = np.zeros(len(frame))
        reference = (frame["engine_reference_torque_nm"].to_numpy(dtype=float) if "engine_reference_torque_nm" in frame
                     else np.full(len(frame), getattr(vehicle, "engine_reference_torque_nm", None) or np.nan))
        sigma_nm = TORQUE_OFFSET_UNCERTAINTY * reference if offset_sigma_nm is None else offset_sigma_nm
        if "engine_speed_rpm" in frame:
            offset = wheel_force_from_torque_n(wheel_torque_from_engine_nm(
                sigma_nm, frame["engine_speed_rpm"].to_numpy(dtype=float), speed,
                vehicle.wheel_radius_m, vehicle.driveline_efficiency), vehicle.wheel_radius_m) / mass
    return np.hypot(np.nan_to_num(wind), np.nan_to_num(offset))


def _add_road_load_uncertainty(result: GradientResult, frame, virtual, vehicle, mass, spacing_m,
                               offset_sigma_nm: float | None = None):
    """With a given mass and no height source, widen the gradient's sigma by the road load the force
    balance cannot know (`road_load_sigma_mps2`) over g where it carries the gradient: with nothing
    to tie it, a head wind reads as a steeper road (can-only harsh regional seed 2: its 9.8 m/s wind
    and 1.7 % torque offset made the whole drive +0.1 m/s², +1 %-pt, with a stated sigma of
    0.3-0.6 %-pt)."""
    specific = np.where(np.isfinite(virtual), road_load_sigma_mps2(frame, vehicle, mass, offset_sigma_nm), np.nan)
    _widen_where_measured(result, frame, specific, spacing_m)


def estimate_gradient_for_log(frame: pd.DataFrame, dem, settings: GradientSettings = GradientSettings(),
                              vehicle=None) -> GradientResult:
    """The gradient stage's estimate: with the force balance as the accelerometer where the log
    has neither an IMU nor a barometer and a vehicle file and engine torque are there, else
    `estimate_gradient`. With a barometer the force balance is left out: its errors are
    systematic (mass, torque gain, wind, auxiliaries), the smoother takes them for noise, and on the
    accuracy matrix it made the barometer-led gradient worse (``docs/estimation.md``).

    The road is gridded by the signals' ``distance_m``, which the kinematics stage gives at the GPS
    track's scale where the track measures the wheel's (`kinematics.add_kinematics`): each height is
    the one at its true place, so over the wheel's own distance the gradient would be the true one
    over (1 + ε)."""
    has_imu = "accel_x_mps2" in frame.columns and frame["accel_x_mps2"].notna().any()
    has_baro = "pressure_pa" in frame.columns and frame["pressure_pa"].notna().any()
    has_torque = "engine_torque_nm" in frame.columns and frame["engine_torque_nm"].notna().any()
    if has_imu or has_baro or vehicle is None or not has_torque:
        return estimate_gradient(frame, dem, settings)
    try:
        return estimate_gradient_force_balance(frame, dem, vehicle, settings)
    except UserError as exc:
        if "needs a DEM" in str(exc):
            raise
        result = estimate_gradient(frame, dem, settings)
        result.notes.append(f"force balance not used: {exc}")
        return result
