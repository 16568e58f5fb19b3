"""Road height and gradient on a distance grid: map-matching, barometer, IMU, the paper's fusion
(5)-(8) and the state-space smoother (``kalman``, ``smoother``) that is the default."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from .. import checks, gnss_accuracy, kinematics
from ..errors import UserError
from ..geodesy import local_east_north_m
from . import grid as distance_grid
from . import kalman, sources, standstill_bias
from .posterior import GradientPosterior, gradient_posterior
from .smoother import (KNOWN_BIAS_MPS2, GradientSmoother, Measurements, SmootherSettings, bin_times, clock_times,
                       standstill_bins)

METHODS = ("smoother", "paper")


@dataclass(frozen=True)
class GradientSettings:
    """Grid and smoothing lengths [m]; the defaults are measured on the virtual truck
    (see ``docs/estimation.md``)."""

    spacing_m: float = 10.0
    gradient_method: str = "smoother"
    """Which estimate becomes ``gradient_pct``/``height_m``: "smoother" (Kalman smoother over
    distance, all sources) or "paper" (fusion (8)); both are always written as columns."""
    smoother: SmootherSettings = SmootherSettings()
    map_sigma_m: float | None = None
    """Gaussian sigma of the map-matching fit [m]; None: chosen per drive among
    ``map_sigma_candidates_m`` as the one whose map gradient agrees best with the barometric one
    (``default_map_sigma_m`` without a barometer)."""
    map_sigma_candidates_m: tuple[float, ...] = (75.0, 100.0, 150.0, 200.0, 300.0, 400.0, 600.0)
    default_map_sigma_m: float = 150.0
    baro_sigma_m: float = 40.0
    imu_sigma_m: float = 40.0
    anchor_sigma_m: float = 1500.0
    gps_jump_tolerance_m: float = 25.0
    gps_reacquire_s: float = 30.0
    stuck_sensor_s: float = 5.0
    use_air_temperature: bool = False
    """Scale barometric height steps by T_air / T_standard; off by default because a logger's
    temperature sensor sits in a warm box (measured: it made the virtual truck's gradient worse)."""
    imu_standstill_steps: bool = False
    """Take the steps of the accelerometer's bias that long standstills show out of its channel
    before the smoother and put them back into the bias it states (`standstill_bias`): the
    smoother's bias cannot step while the truck stands. Off by default: on drives never tuned on
    (the matrix's seeds 4-7) it made the mass's tails after a stop worse and its σ less honest
    than the standstill's change held in σ alone (docs/estimation.md, stop 40)."""


@dataclass
class GradientResult:
    grid: pd.DataFrame
    """One row per grid point: distance_m and each source's height/gradient/weight."""
    samples: dict[str, np.ndarray]
    """Columns for the signals table (height_m, gradient_pct and each source's)."""
    notes: list[str] = field(default_factory=list)
    map_sigma_m: float | None = None
    """The map-matching smoothing used [m] (None without map-matching)."""
    smoother: dict | None = None
    """The smoother's data-estimated noise levels and calibrations (None if it could not run)."""
    settings: GradientSettings | None = None
    """The settings it was estimated with."""
    sensor_set: str | None = None
    """The sensors the log held (`sensor_sets.sensor_set`), set by the gradient stage."""
    posteriors: tuple[GradientPosterior, ...] = ()
    """The smoother's posterior of the gradient errors along the grid, where its σ is that
    posterior's own (`posterior`), each naming the gradient samples it describes; for
    `mass.estimate_mass`'s ``gradient_posteriors``."""

    def __post_init__(self):
        if self.smoother is None:
            self.smoother = {}

    def summary(self) -> dict:
        """Sources, method, the gradient's range, height gained, the smoother's calibrations, notes."""
        settings = self.settings or GradientSettings()
        grid = self.grid
        gradient = grid["gradient_pct"].to_numpy()
        return {
            "grid_spacing_m": settings.spacing_m,
            "sensor_set": self.sensor_set,
            "sources": [s for s, c in (("map", "gradient_map_pct"), ("baro", "gradient_baro_pct"),
                                       ("imu", "gradient_imu_pct"), ("force_balance", "gradient_force_balance_pct"))
                        if c in grid.columns],
            "method": settings.gradient_method,
            "mean_map_weight": float(np.mean(grid["weight_map"])),
            "smoother": self.smoother,
            "map_sigma_m": self.map_sigma_m,
            "gradient_pct": {"mean": float(np.nanmean(gradient)), "min": float(np.nanmin(gradient)),
                             "max": float(np.nanmax(gradient))},
            "height_gain_m": float(np.sum(np.clip(np.diff(grid["height_m"].to_numpy()), 0, None))),
            "notes": self.notes,
        }


def _column(frame: pd.DataFrame, name: str) -> np.ndarray | None:
    if name not in frame.columns or frame[name].isna().all():
        return None
    return frame[name].to_numpy(dtype=float)


def _sample_rate_hz(time_s: np.ndarray) -> float:
    steps = np.diff(time_s)
    steps = steps[steps > 0]
    return 1.0 / float(np.median(steps)) if len(steps) else 1.0


def estimate_gradient(frame: pd.DataFrame, dem=None, settings: GradientSettings = GradientSettings()) -> GradientResult:
    """Heights [m] and gradients [%] of every available source and their fusion (8).

    ``frame`` is a signals table (time_s, speed_mps; distance_m/accel_mps2 are computed if absent);
    ``dem`` anything with ``height_m(lat, lon)`` (`analysis.dem.open_dem`). Raises `UserError`
    when neither a DEM with GPS nor a barometer is available, or no sample is valid.
    """
    if settings.gradient_method not in METHODS:
        raise UserError(f"gradient: unknown method {settings.gradient_method!r} (choose {' or '.join(METHODS)})")
    if isinstance(settings.smoother, dict):
        settings = replace(settings, smoother=SmootherSettings(**settings.smoother))
    notes: list[str] = []
    frame, dop_note = gnss_accuracy.with_dop_accuracy(frame)
    if dop_note:
        notes.append(dop_note)
    time_s = frame["time_s"].to_numpy(dtype=float)
    speed = frame["speed_mps"].to_numpy(dtype=float)
    distance = _column(frame, "distance_m")
    if distance is None:
        distance = kinematics.distance_m(time_s, speed)
    valid = np.isfinite(distance)
    if "valid" in frame.columns:
        valid &= frame["valid"].to_numpy(dtype=bool)
    if not valid.any():
        raise UserError("gradient: no valid samples (no finite distance); check speed_mps and the valid column")
    spacing = settings.spacing_m
    index = np.where(valid, distance_grid.grid_index(distance, spacing), -1)
    n_bins = int(index.max()) + 1
    checks.rows(n_bins, f"the {spacing:g} m distance grid of {distance[valid].max() / 1000:.3g} km",
                "is speed_mps in m/s and time_s in s?")
    s_grid = np.arange(n_bins) * spacing
    out = pd.DataFrame({"distance_m": s_grid})

    map_bins, map_accuracy = _map_bins(frame, dem, distance, valid, index, n_bins, settings, notes)
    map_level = map_slope = None
    weight_map = np.zeros(n_bins)
    map_sigma = None
    if map_bins is not None:
        map_sigma = settings.map_sigma_m or settings.default_map_sigma_m
        map_level, map_slope, weight_map = _map_fit(*map_bins, spacing, map_sigma)

    baro_level = baro_slope = None
    bin_baro = _baro_bins(frame, speed, time_s, index, n_bins, settings, notes)
    if bin_baro is not None:
        offset = _baro_offset(frame, bin_baro, map_level, weight_map, index, n_bins, s_grid, settings)
        anchored = bin_baro + offset
        baro_level, baro_slope, _ = distance_grid.local_linear(anchored, np.isfinite(anchored).astype(float),
                                                               spacing, settings.baro_sigma_m)
        if map_bins is not None and settings.map_sigma_m is None:
            map_sigma = _best_map_sigma(*map_bins, spacing, baro_slope, weight_map, settings.map_sigma_candidates_m)
            map_level, map_slope, weight_map = _map_fit(*map_bins, spacing, map_sigma)
            notes.append(f"map-matching smoothed with sigma {map_sigma:g} m (best agreement with the barometer)")
        out["height_baro_m"] = baro_level
        out["gradient_baro_pct"] = 100 * baro_slope
    if map_level is not None:
        out["height_map_m"] = map_level
        out["gradient_map_pct"] = 100 * map_slope
    out["weight_map"] = weight_map

    accel_imu = _column(frame, "accel_x_mps2")
    imu_excess = None
    bias_steps = []
    if accel_imu is not None:
        accel = _column(frame, "accel_mps2")
        accel = kinematics.acceleration_mps2(time_s, speed) if accel is None else accel
        imu_excess = sources.imu_excess_mps2(accel_imu, accel, time_s)
        stated = _column(frame, "accel_x_excess_mps2")
        if stated is not None:  # a stand-in that states a_x - dv/dt itself (`force_balance`)
            imu_excess = stated
        bias_steps = (standstill_bias.standstill_steps(time_s, speed, accel_imu)
                      if settings.imu_standstill_steps else [])
        step_offset, step_std, imu_clock = standstill_bias.step_offsets(time_s, bias_steps)
        imu_excess = imu_excess - step_offset
        if bias_steps:
            notes.append(f"IMU: its bias stepped by {', '.join(f'{1000 * st.step_mps2:+.1f}' for st in bias_steps)} "
                         f"mm/s² over {len(bias_steps)} long standstill(s) (the reading's change where the truck "
                         f"stood): taken out of the accelerometer before the smoother, put back into imu_bias_mps2")
        sin_angle = distance_grid.bin_mean(index, sources.imu_sin_angle(accel_imu, accel), n_bins)
        level, _, _ = distance_grid.local_linear(sin_angle, np.ones(n_bins), spacing, settings.imu_sigma_m)
        out["gradient_imu_pct"] = 100 * np.tan(np.arcsin(np.clip(level, -1, 1)))

    paper_notes: list[str] = []
    if map_slope is None and baro_slope is None:
        known_bias = imu_excess is not None and settings.smoother.imu_bias_prior_sigma_mps2 <= KNOWN_BIAS_MPS2
        if not _has_gps_altitude(frame) and known_bias:
            notes.append("no height source: the gradient is the accelerometer's with its bias known beforehand")
        elif not _has_gps_altitude(frame):
            raise UserError("gradient: needs a DEM (dem_dir) with GPS positions, a barometer (pressure_pa) or "
                            "GPS altitude with its accuracy (gps_altitude_m, gps_v_acc_m); this input has none")
        else:
            notes.append("GPS altitude is the only height source: the gradient is its smoothed slope, good to the "
                         "stated gradient_smooth_std_pct (the paper's fusion (8) needs a DEM or a barometer)")
        if settings.gradient_method == "paper":
            notes.append("gradient_pct is the smoother's: the paper's fusion has no source here")
            settings = replace(settings, gradient_method="smoother")
        fused_slope = np.full(n_bins, np.nan)
        fused_height = np.full(n_bins, np.nan)
    else:
        fused_slope = _fuse(map_slope, weight_map, baro_slope, s_grid, paper_notes)
        fused_height = _integrate(fused_slope, spacing)
        fused_height += _height_offset(fused_height, map_level, weight_map, baro_level)
    out["height_paper_m"] = fused_height
    out["gradient_paper_pct"] = 100 * fused_slope

    measurements = _measurements(frame, index, n_bins, time_s, bin_baro, map_bins, map_accuracy, imu_excess, settings,
                                 notes)
    if imu_excess is not None and _column(frame, "accel_x_scale_var_m2ps4") is None:
        # a real accelerometer's (the force balance standing in for one has no force standing)
        changes = sources.standstill_bias_changes(time_s, speed, imu_excess)
        measurements = replace(measurements, standstill_bias_changes=tuple(
            (int(index[start]), change, variance) for start, change, variance in changes if 0 <= index[start] < n_bins))
    if imu_excess is not None and bias_steps:
        # the bias's change over the measured standstills is in the steps: its rate acts on the rest
        measurements = replace(measurements, clock_s=clock_times(index, imu_clock, measurements.dt_s))
    smoothed = GradientSmoother(measurements, settings.smoother).estimate()
    notes.extend(smoothed.notes)
    smooth_height = _integrate(smoothed.gradient, spacing)
    out["height_smooth_m"] = smooth_height + np.mean(smoothed.height_m - smooth_height)
    out["gradient_smooth_pct"] = 100 * smoothed.gradient
    out["gradient_smooth_std_pct"] = 100 * smoothed.gradient_std
    out["baro_drift_m"] = smoothed.drift_m if bin_baro is not None else np.nan
    out["imu_bias_mps2"] = smoothed.imu_bias_mps2 if imu_excess is not None else np.nan
    out["imu_bias_std_mps2"] = smoothed.imu_bias_std_mps2 if imu_excess is not None else np.nan
    out["imu_bias_ramp_std_mps2"] = smoothed.imu_bias_ramp_std_mps2 if imu_excess is not None else np.nan
    out["imu_bias_shared_std_mps2"] = (smoothed.imu_bias_shared_std_mps2
                                       if imu_excess is not None and smoothed.imu_bias_shared_std_mps2 is not None
                                       else np.nan)
    if smoothed.imu_scale is not None:
        out["force_balance_log_scale"] = smoothed.imu_scale
        out["force_balance_log_scale_std"] = smoothed.imu_scale_std
    out["map_gated"] = smoothed.map_gated
    for name, weight in smoothed.weights.items():
        out[f"weight_smooth_{name}"] = weight
    if settings.gradient_method == "smoother":
        out["height_m"], out["gradient_pct"] = out["height_smooth_m"], out["gradient_smooth_pct"]
    else:
        notes.extend(paper_notes)
        out["height_m"], out["gradient_pct"] = out["height_paper_m"], out["gradient_paper_pct"]

    samples = {name: np.interp(distance, s_grid, out[name].to_numpy(), left=np.nan, right=np.nan)
               for name in out.columns if name != "distance_m"}
    if imu_excess is not None and bias_steps:
        # per sample, not per grid point: a standstill's samples share one point, its step is in time
        samples["imu_bias_mps2"] = samples["imu_bias_mps2"] + step_offset
        samples["imu_bias_std_mps2"] = np.hypot(samples["imu_bias_std_mps2"], step_std)
        on_grid = distance_grid.bin_mean(index, step_offset, n_bins)
        have = np.isfinite(on_grid)
        out["imu_bias_mps2"] += np.interp(np.arange(n_bins), np.flatnonzero(have), on_grid[have])
    posteriors = () if smoothed.gradient_posterior is None else (
        gradient_posterior(*smoothed.gradient_posterior, distance, spacing, samples["gradient_smooth_pct"]),)
    return GradientResult(grid=out, samples=samples, notes=notes, map_sigma_m=map_sigma, posteriors=posteriors,
                          smoother={"method": settings.gradient_method, **smoothed.noise,
                                    "imu_bias_mps2": (float(np.median(out["imu_bias_mps2"]))
                                                      if imu_excess is not None else None),
                                    "map_gated_km": float(smoothed.map_gated.sum() * spacing / 1000),
                                    "mean_weights": {k: float(np.mean(v)) for k, v in smoothed.weights.items()}})


def _has_gps_altitude(frame) -> bool:
    return _column(frame, "gps_altitude_m") is not None and _column(frame, "gps_v_acc_m") is not None


def _bin_count(index, values, n_bins):
    ok = (index >= 0) & np.isfinite(values)
    return np.bincount(index[ok], minlength=n_bins)[:n_bins].astype(float)


def _measurements(frame, index, n_bins, time_s, bin_baro, map_bins, map_accuracy, imu_excess, settings, notes):
    """The smoother's per-bin measurements (`smoother.Measurements`); says which sources are missing."""
    z = np.full((n_bins, kalman.N_MEASUREMENTS), np.nan)
    count = np.zeros((n_bins, kalman.N_MEASUREMENTS))
    h_acc = v_acc = np.full(n_bins, np.nan)
    imu_scale_var = scale_regressor = scale_reset_var = None
    if bin_baro is not None:
        z[:, kalman.BARO] = bin_baro
        count[:, kalman.BARO] = np.isfinite(bin_baro) * map_accuracy["rate_count"]
    if map_bins is not None:
        z[:, kalman.DEM] = map_bins[0]
        count[:, kalman.DEM] = np.isfinite(map_bins[0])
        h_acc = map_accuracy["h_acc"]
    if imu_excess is not None:
        z[:, kalman.IMU] = distance_grid.bin_mean(index, imu_excess, n_bins)
        count[:, kalman.IMU] = _bin_count(index, imu_excess, n_bins)
        scale_var = _column(frame, "accel_x_scale_var_m2ps4")
        if scale_var is not None:
            imu_scale_var = distance_grid.bin_mean(index, np.sqrt(scale_var), n_bins) ** 2
        scale_regressor, scale_reset_var = _scale_state_bins(frame, index, imu_excess, n_bins)
    else:
        notes.append("no IMU (accel_x_mps2): smoother without the accelerometer")
    altitude, v_acc_samples = _column(frame, "gps_altitude_m"), _column(frame, "gps_v_acc_m")
    if altitude is not None and v_acc_samples is not None:
        altitude = np.where(np.isfinite(v_acc_samples), altitude, np.nan)
        z[:, kalman.GPS] = distance_grid.bin_mean(index, altitude, n_bins)
        count[:, kalman.GPS] = _bin_count(index, altitude, n_bins)
        v_acc = distance_grid.bin_mean(index, v_acc_samples, n_bins)
    else:
        notes.append("no GPS altitude with accuracy (gps_altitude_m, gps_v_acc_m): smoother without it")
    missing_gps = np.isnan(z[:, kalman.GPS]).mean() if altitude is not None else 0.0
    if 0.01 < missing_gps < 1:
        notes.append(f"no GPS altitude on {100 * missing_gps:.0f} % of the distance (outages): "
                     f"barometer and IMU carry the profile there")
    speed = frame["speed_mps"].to_numpy(dtype=float)
    dt = bin_times(index, speed, n_bins, settings.spacing_m)
    return Measurements(z=z, count=count, h_acc_m=h_acc, v_acc_m=v_acc, dt_s=dt, spacing_m=settings.spacing_m,
                        stopped=standstill_bins(index, speed, n_bins), clock_s=clock_times(index, time_s, dt),
                        imu_scale_var=imu_scale_var,
                        imu_scale_regressor=scale_regressor, imu_scale_reset_var=scale_reset_var)


def _scale_state_bins(frame, index, imu_excess, n_bins):
    """The smoother's scale state from the columns `force_balance` adds: the regressor's bin means
    (``accel_x_scale_regressor_mps2`` where the accelerometer channel measured) and, at each grid
    point where a new mass segment (``accel_x_scale_segment``) starts, its prior variance
    (``accel_x_scale_sigma``², of the log scale); (None, None) without those columns."""
    regressor = _column(frame, "accel_x_scale_regressor_mps2")
    segment = _column(frame, "accel_x_scale_segment")
    sigma = _column(frame, "accel_x_scale_sigma")
    if regressor is None or segment is None or sigma is None:
        return None, None
    measured = np.isfinite(imu_excess)
    bins = distance_grid.bin_mean(index, np.where(measured, regressor, np.nan), n_bins)
    labelled = (index >= 0) & np.isfinite(segment) & (segment >= 0)
    label = np.full(n_bins, -1.0)
    np.maximum.at(label, index[labelled], segment[labelled])
    variance = np.zeros(n_bins)
    np.maximum.at(variance, index[labelled], np.nan_to_num(sigma[labelled]) ** 2)
    known = np.flatnonzero(label >= 0)
    if len(known) == 0:
        return None, None
    # a bin without a segment's samples belongs to the last segment before it (the first's before any)
    last = known[np.clip(np.searchsorted(known, np.arange(n_bins), side="right") - 1, 0, None)]
    starts = np.concatenate([[True], label[last][1:] != label[last][:-1]])
    return bins, np.where(starts, variance[last], 0.0)


def _map_bins(frame, dem, distance, valid, index, n_bins, settings, notes):
    """Per-bin DEM height [m] at the GPS fixes and per-bin accuracy weight, or None without map."""
    lat, lon = _column(frame, "latitude_deg"), _column(frame, "longitude_deg")
    h_acc = _column(frame, "gps_h_acc_m")
    accuracy = {"h_acc": (distance_grid.bin_mean(index, h_acc, n_bins) if h_acc is not None
                          else np.full(n_bins, np.nan)),
                "rate_count": np.ones(n_bins)}
    pressure = _column(frame, "pressure_pa")
    if pressure is not None:
        accuracy["rate_count"] = _bin_count(index, np.where(valid, pressure, np.nan), n_bins)
    if dem is None:
        notes.append("no DEM: map-matching off")
        return None, accuracy
    if lat is None or lon is None:
        notes.append("no GPS position columns (latitude_deg, longitude_deg): map-matching off")
        return None, accuracy
    time_s = frame["time_s"].to_numpy(dtype=float)
    east, north = local_east_north_m(lat, lon)
    jumped = sources.gps_outliers(east, north, distance, time_s, settings.gps_jump_tolerance_m,
                                  settings.gps_reacquire_s)
    n_jumps = int(np.sum(jumped & np.isfinite(lat)))
    if n_jumps:
        notes.append(f"{n_jumps} GPS fixes left out of map-matching (jumped away from the wheel-speed track)")
    fix_ok = valid & ~jumped
    terrain = np.full(len(frame), np.nan)
    terrain[fix_ok] = dem.height_m(lat[fix_ok], lon[fix_ok])
    h_acc, v_acc = _column(frame, "gps_h_acc_m"), _column(frame, "gps_v_acc_m")
    if h_acc is None or v_acc is None:
        notes.append("no GPS accuracy columns: map weight 1 wherever there is a fix")
        accuracy_weight = np.ones(len(frame))
    else:
        accuracy_weight = sources.map_weight(h_acc, v_acc)
    accuracy_weight = np.where(np.isfinite(terrain), accuracy_weight, np.nan)
    return (distance_grid.bin_mean(index, terrain, n_bins),
            np.nan_to_num(distance_grid.bin_mean(index, accuracy_weight, n_bins))), accuracy


def _baro_bins(frame, speed, time_s, index, n_bins, settings, notes):
    """Per-bin barometric height (6) [m], stuck readings dropped and standstill frozen, or None."""
    pressure = _column(frame, "pressure_pa")
    if pressure is None:
        notes.append("no pressure_pa: barometric height off")
        return None
    pressure = sources.stuck_to_nan(pressure, max(3, int(settings.stuck_sensor_s * _sample_rate_hz(time_s))))
    baro = sources.freeze_at_standstill(sources.barometric_height_m(pressure), speed, time_s)
    bin_baro = distance_grid.bin_mean(index, baro, n_bins)
    temperature = _column(frame, "air_temperature_c")
    if temperature is not None and settings.use_air_temperature:
        bin_baro = _temperature_corrected(bin_baro, distance_grid.bin_mean(index, temperature, n_bins))
    missing = np.isnan(bin_baro).mean()
    if missing == 1:
        notes.append("pressure_pa never changes while driving (a stopped sensor): barometric height off")
    elif missing > 0.01:
        notes.append(f"barometer missing on {100 * missing:.0f} % of the distance")
    return bin_baro if missing < 1 else None


def _baro_offset(frame, bin_baro, map_level, weight_map, index, n_bins, s_grid, settings):
    """Baseline [m] added to the barometric height: the w_map-weighted local level of
    (map - baro) over ``anchor_sigma_m``; without a map, the median offset to the GPS altitude."""
    if map_level is not None and np.any(weight_map > 0):
        offset, _, _ = distance_grid.local_linear(map_level - bin_baro, weight_map, settings.spacing_m,
                                                  settings.anchor_sigma_m)
        return _fill_nan(s_grid, offset)
    gps_altitude = _column(frame, "gps_altitude_m")
    if gps_altitude is None:
        return np.zeros(n_bins)
    gap = distance_grid.bin_mean(index, gps_altitude, n_bins) - bin_baro
    return np.full(n_bins, np.nanmedian(gap) if np.isfinite(gap).any() else 0.0)


MAX_ROAD_SLOPE = 0.30
"""Steepest gradient of a road a truck drives [-] (public roads stay below some 25-35 %)."""


def _fuse(map_slope, weight_map, baro_slope, s_grid, notes):
    """(8): (w_map g_map + w_baro g_baro) / (w_map + w_baro) [-]; bins with no source interpolated."""
    n_bins = len(s_grid)
    w_map = weight_map if map_slope is not None else np.zeros(n_bins)
    if map_slope is not None:
        steep = np.abs(np.nan_to_num(map_slope)) > MAX_ROAD_SLOPE
        if steep.any():
            notes.append(f"map gradient above {100 * MAX_ROAD_SLOPE:.0f} % (no road is that steep) on "
                         f"{100 * steep.mean():.1f} % of the distance: the map is left out there")
            w_map = np.where(steep, 0.0, w_map)
    w_baro = sources.WEIGHT_BARO * np.isfinite(baro_slope) if baro_slope is not None else np.zeros(n_bins)
    g_map = np.nan_to_num(map_slope) if map_slope is not None else np.zeros(n_bins)
    g_baro = np.nan_to_num(baro_slope) if baro_slope is not None else np.zeros(n_bins)
    total = w_map + w_baro
    with np.errstate(invalid="ignore", divide="ignore"):
        fused = np.where(total > 0, (w_map * g_map + w_baro * g_baro) / total, np.nan)
    if np.isnan(fused).any():
        notes.append(f"no source on {100 * np.isnan(fused).mean():.1f} % of the distance: gradient "
                     f"interpolated across")
        fused = _fill_nan(s_grid, fused, fill=0.0)
    return fused


def _map_fit(bin_terrain, bin_weight, spacing_m, sigma_m):
    """Map-matching height [m], slope [-] and w_map of (8) on the grid, for one smoothing sigma [m]:
    a fit weighted by GPS accuracy, and w_map as the accuracy weight the kernel saw."""
    level, slope, _ = distance_grid.local_linear(bin_terrain, bin_weight, spacing_m, sigma_m)
    kernel_weight, _, _ = distance_grid.local_linear(bin_weight, np.isfinite(bin_terrain), spacing_m, sigma_m)
    return level, slope, np.clip(np.nan_to_num(kernel_weight), 0, 1) * np.isfinite(slope)


def _best_map_sigma(bin_terrain, bin_weight, spacing_m, baro_slope, weight_map, candidates_m):
    """The candidate sigma [m] whose map gradient has the smallest w_map-weighted RMS difference
    to the barometric gradient. The DEM holds terrain, not road: cuttings and embankments of a few
    metres every few hundred metres are map-gradient errors the barometer does not have, while
    the road's own hills are in both; the best agreement marks where that trade-off lies."""
    best, best_rms = candidates_m[0], np.inf
    trusted = weight_map * np.isfinite(baro_slope)
    if trusted.sum() == 0:
        return candidates_m[len(candidates_m) // 2]
    for sigma in candidates_m:
        _, slope, _ = distance_grid.local_linear(bin_terrain, bin_weight, spacing_m, sigma)
        difference = np.nan_to_num(slope - baro_slope)
        rms = np.sum(trusted * np.isfinite(slope) * difference ** 2) / trusted.sum()
        if rms < best_rms:
            best, best_rms = sigma, rms
    return float(best)


def _temperature_corrected(height_m, temperature_c):
    """Height differences of (6) scaled by T_actual / T_standard (the hypsometric equation)."""
    ratio = (np.asarray(temperature_c) + 273.15) / sources.standard_temperature_k(height_m)
    ratio = np.where(np.isfinite(ratio), ratio, 1.0)
    steps = np.diff(height_m) * ratio[1:]
    first = np.flatnonzero(np.isfinite(height_m))
    if len(first) == 0:
        return height_m
    corrected = np.concatenate([[0.0], np.nancumsum(steps)]) + height_m[first[0]]
    return np.where(np.isfinite(height_m), corrected, np.nan)


def _fill_nan(x, y, fill=None):
    ok = np.isfinite(y)
    if not ok.any():
        return np.full_like(y, 0.0 if fill is None else fill)
    return np.interp(x, x[ok], y[ok])


def _integrate(slope, spacing_m):
    """Height [m] whose central derivative on the grid is ``slope``: trapezoidal integral."""
    steps = 0.5 * (slope[1:] + slope[:-1]) * spacing_m
    return np.concatenate([[0.0], np.cumsum(steps)])


def _height_offset(relative_m, map_level, weight_map, baro_level):
    """Constant that puts the integrated height on the map (weighted) or barometric level."""
    for level, weight in ((map_level, weight_map), (baro_level, None)):
        if level is None:
            continue
        w = np.isfinite(level) * (1.0 if weight is None else weight)
        if w.sum() > 0:
            return float(np.sum(w * np.nan_to_num(level - relative_m)) / w.sum())
    return 0.0
