"""The smoother's measurements, their noise levels, the map gate and the sources' weights.

Every noise level that the data can tell is taken from the data: the barometer's and the IMU's
from their own residuals, the DEM's error size and correlation length from its disagreement with
the barometric/IMU profile. The DEM is gated out where that disagreement is consistently too large
for its error model over a window (a chi-square test over the correlation length): a bridge over
a valley, a tunnel under a mountain, a deep cutting, a canopy patch.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d
from scipy.stats import chi2

from ..road_load import G_MPS2
from ..runs import true_runs
from . import gps_altitude, kalman

CHI2_MEDIAN_1DOF = 0.454936
KNOWN_BIAS_MPS2 = 0.05
"""An accelerometer bias known to this [m/s²] (0.3 %-pt of gradient) needs no height source."""
SOURCE_NAMES = ("baro", "map", "imu", "gps")
MIN_HIDDEN_SAMPLES = 20
"""Fewer force-balance bins hidden by moved gaps than this tell no curvature
(`GradientSmoother._curvature_across_force_gaps`)."""
IMU_LED_AXES = ("bias_rate_psd",)
"""What the likelihood still chooses after the IMU-led EM (`GradientSmoother._imu_led_noise`) has
chosen the curvature and the IMU noise."""


@dataclass(frozen=True)
class SmootherSettings:
    """Process noises of the state model (``kalman``) and the robust tests; defaults from the
    physics of roads and sensors (``docs/estimation.md``)."""

    curvature_psd: float | None = None
    """Gradient random walk [1/m]; None: chosen per drive among ``curvature_candidates`` (how
    hilly the road is, from the data): with an IMU, the one whose barometer/GPS-only gradient best
    predicts the accelerometer (independent noise, so this is the gradient's own error); without,
    by the likelihood of the barometer/GPS innovations."""
    curvature_candidates: tuple[float, ...] = (3e-9, 1e-8, 3e-8, 1e-7, 3e-7, 1e-6, 3e-6, 1e-5, 3e-5)
    """1e-6 is one sigma of a 1 %-point change per 100 m (a 10 km vertical curve); 1e-5 and 3e-5
    are an urban street's (the matrix's urban roads: 5e-6 to 1.3e-5 over 50-200 m)."""
    drift_rate_psd: float = 1e-8
    """Barometric drift-rate random walk [m²/s³]: a 1 hPa/h front building up over an hour."""
    bias_psd: float = 1e-8
    """IMU bias random walk [(m/s²)²/s], the floor: temperature drift of a few mm/s² per hour.
    A faster walk is chosen per drive by likelihood among ``bias_psd_candidates``."""
    bias_psd_candidates: tuple[float, ...] = (1e-8, 1e-7, 1e-6, 1e-5)
    """The warm-up of a cab-mounted IMU (0.5-1.5 mg/K over 15 K in half an hour) walks by
    ~1e-6 (m/s²)²/s; 1e-5 is a bias that changes by a few cm/s² within minutes."""
    bias_rate_prior_sigma_mps3: float = 1.2e-4
    """Prior sigma of the IMU bias's rate [m/s³] (`kalman.BIAS_RATE`): a MEMS accelerometer's
    offset moves by up to 1.5 mg/K with temperature, and a cab warms its IMU by ~15 K with a
    half-hour time constant, 0.5 K/min at the start: 1.5e-3 g × 8.3 mK/s. 0: no rate state."""
    bias_rate_psd_candidates: tuple[float | None, ...] = (None, 0.0, 1e-13)
    """Random walk of the bias's rate [(m/s³)²/s], chosen by likelihood. None: no rate state (a
    steady bias); 0: a constant rate, a linear ramp (a warm-up over a drive shorter than the cab's
    half hour); 1e-13: the rate changes by 1.9e-5 m/s³ in an hour, the warm-up's decay over a long
    drive (on a 70-minute synthetic warm-up 96 % of the bins inside ±2σ with 0, 99 % with 1e-13).
    1e-12 and faster let the rate trade with the gradient within minutes (``docs/estimation.md``)."""
    bias_rate_probability: float = 1e-3
    """False-alarm probability of the likelihood-ratio test (chi-square, 1 dof) a bias-rate
    candidate must pass against the simpler one before it (the map gate's 1e-3). The model it
    keeps gives the notes; height, gradient and bias are averaged over the models with and without
    a rate (`GradientSmoother._averaged_over_the_rate`)."""
    offset_psd: float | None = None
    """Random walk of the barometric offset d while driving [m²/s] (the cab's overpressure follows
    the ventilation's level and the airflow; a weather front is the drift rate). None: chosen per
    drive by the likelihood of all sources' innovations among ``offset_psd_candidates``."""
    offset_psd_candidates: tuple[float, ...] = (0.0, 1e-5, 1e-4, 1e-3, 1e-2)
    imu_noise_factors: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0, 4.0)
    """Factors on the IMU noise estimated from its residual, searched with the walks."""
    likelihood_rounds: int = 3
    """Rounds of the coordinate ascent over the noise levels (`GradientSmoother._noise_by_likelihood`)."""
    """0: the barometer's offset only drifts smoothly (front) and steps at standstills; 1e-3 m²/s
    is 2.5 m of cab-pressure change (30 Pa) in an hour's ~6 blower steps."""
    gps_sigma_factor: float = 3.0
    """GPS altitude sigma = factor * v_acc: its errors are correlated over tens of seconds, so it is
    taken weakly."""
    gps_multipath_share: bool = False
    """Scale the receiver's stated variance above its open-sky level (multipath in a street
    canyon) by how much of it GPS altitude's own residual shows (`gps_altitude.multipath_share`,
    `GradientSmoother.estimate`); set where the force balance stands in for the accelerometer."""
    terrain_cross_slope: float = 0.1
    """DEM height error per metre of horizontal GPS error [-] (terrain slope next to the road)."""
    dem_white_fraction: float = 0.2
    """Floor of the DEM's uncorrelated error as a fraction of its correlated error."""
    gate_probability: float = 1e-3
    """False-alarm probability of the map gate's chi-square test per window."""
    gate_detrend_m: float = 2000.0
    """Running-median length [m] that takes the slow barometric drift out of the DEM residual."""
    imu_bias_prior_sigma_mps2: float = 0.5
    """Prior sigma of the accelerometer's bias [m/s²]: unknown (0.5, a 3° mounting pitch) for an
    IMU; the force balance with a given mass (`force_balance`) knows it to the rolling
    resistance's uncertainty, and at or below `KNOWN_BIAS_MPS2` it is a height source on its own."""
    imu_led_start_sigma_mps2: float = 0.005
    """Without a barometer: the IMU noise's estimate starts here [m/s²] (below any IMU's noise
    per 10 m bin) and climbs to its fixed point (`GradientSmoother._imu_led_noise`)."""
    imu_led_iterations: int = 12
    bias_block_s: float = 300.0
    """Driving time [s] of the blocks in which the IMU-led smoother checks its bias for a drift
    (`GradientSmoother._bias_drift_between_blocks`): a cab's warm-up moves it within minutes."""
    bias_min_blocks: int = 3
    """Fewer blocks than this (a drive under 15 minutes) tell no drift."""
    force_balance: bool = False
    """The accelerometer channel is the force balance (`force_balance`), not an IMU: its noise is
    taken from its own bin-to-bin differences (`GradientSmoother._differenced_noise`), not by the
    IMU-led EM, whose fixed point across the force balance's gaps is the GPS-led one."""
    force_balance_noise_factors: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0, 4.0)
    """Factors on the differenced noise, chosen by likelihood (with the curvature where the force
    balance's gaps tell none, `GradientSmoother._curvature_across_force_gaps`): the force balance's
    errors (wind gusts, auxiliaries, shifts) are correlated over bins, which the differences do
    not see."""
    offset_step_sigma_m: float = 3.0
    """Step of the barometric offset [m] allowed, while driving, where the barometer's innovation
    fails the test below (`GradientSmoother._offset_steps`): the cab's ventilation changes level
    (0-80 Pa at `harsh`, up to 7 m, within a few seconds)."""
    offset_step_probability: float = 1e-4
    """False-alarm probability per grid point of that innovation test (chi-square, 1 dof)."""
    offset_step_rounds: int = 2
    stop_offset_sigma_m: float = 1.0
    """Step of the barometric offset at a standstill [m] (1 m is 12 Pa): the door opens, the
    ventilation restarts at another level, the door slams; the cab's overpressure changes by tens
    of pascals while the height is frozen (`sources.freeze_at_standstill`), and what the freeze
    cannot see is a step the drift's smooth random walk has no room for."""


@dataclass
class Measurements:
    z: np.ndarray
    """(n_bins, 4) bin means: barometric height, DEM height, IMU (a_imu - dv/dt), GPS altitude."""
    count: np.ndarray
    """(n_bins, 4) samples behind each bin mean."""
    h_acc_m: np.ndarray
    v_acc_m: np.ndarray
    dt_s: np.ndarray
    spacing_m: float
    stopped: np.ndarray | None = None
    """(n_bins,) True where the truck stood still in the bin (None: never)."""
    clock_s: np.ndarray | None = None
    """(n_bins,) seconds of clock time from the previous grid point, standstills included: what an
    IMU's temperature, and so its bias's rate (`kalman.BIAS_RATE`), runs on; None: ``dt_s``."""
    imu_scale_var: np.ndarray | None = None
    """(n_bins,) variance [m²/s⁴] the accelerometer channel's scale error adds to each bin (the
    force balance's mass or torque gain, `force_balance.scale_variance_m2ps4`), on top of its noise;
    None: none."""
    imu_scale_regressor: np.ndarray | None = None
    """(n_bins,) with the scale state (`kalman.SCALE`): u [m/s²] of its measurement
    z = e^k (g sin γ + u) - u + b, the force balance's dv/dt + g c_r (bin means); None: no scale state."""
    imu_scale_reset_var: np.ndarray | None = None
    """(n_bins,) the scale state's prior variance [-] where a new mass segment starts (its first
    grid point; the first bin holds the first segment's), 0 elsewhere."""
    standstill_bias_changes: tuple = ()
    """(grid point, change [m/s²], its variance [m⁴/s⁴]) of the accelerometer bias over each
    standstill, as the log's specific force shows it (`sources.standstill_bias_changes`)."""

    def part(self, grid_points: slice) -> "Measurements":
        """The same measurements over ``grid_points`` alone: every per-bin array cut."""
        return replace(self, **{f.name: getattr(self, f.name)[grid_points] for f in fields(self)
                                if isinstance(getattr(self, f.name), np.ndarray)})


@dataclass
class SmootherResult:
    height_m: np.ndarray
    gradient: np.ndarray
    gradient_std: np.ndarray
    drift_m: np.ndarray
    imu_bias_mps2: np.ndarray
    imu_bias_std_mps2: np.ndarray
    imu_scale: np.ndarray | None
    """The scale state per grid point (log of the true mass over the force balance's), None without."""
    imu_scale_std: np.ndarray | None
    dem_error_m: np.ndarray
    map_gated: np.ndarray
    weights: dict[str, np.ndarray]
    noise: dict[str, float]
    notes: list[str]
    imu_bias_ramp_std_mps2: float = 0.0
    """1-sigma [m/s²] of the IMU bias's departure from the smoother's bias that its standstills show
    (`GradientSmoother._standstill_ramp_sigma`); not in ``imu_bias_std_mps2``: it is not one
    error of the drive but one of each stretch between stops. In ``gradient_std`` in the share of
    the gradient the accelerometer carries."""
    imu_bias_shared_std_mps2: np.ndarray | None = None
    """Per grid point, the part [m/s²] of ``imu_bias_std_mps2`` that the bias's error shares with
    the whole drive's (`GradientSmoother._bias_shared_std`), signed: where the error runs against
    the drive's mean it is negative; the rest, sqrt(std² - shared²), is the point's own. None
    without an IMU."""
    gradient_posterior: tuple[np.ndarray, np.ndarray] | None = None
    """The RTS gains (n, ns, ns) and the smoothed covariances' gradient column (n, ns) whose
    cross-covariances are the gradient's errors' along the grid (`posterior.GradientPosterior`);
    only where ``gradient_std`` is that posterior's own: without an accelerometer (with one, σ
    holds the bias's drift between blocks and the rate models' mixture too). None otherwise."""


def bin_times(index: np.ndarray, speed_mps: np.ndarray, n_bins: int, spacing_m: float) -> np.ndarray:
    """Seconds of driving from each grid point to the next (spacing / mean moving speed in the
    bin). Standstill does not count: the barometer is frozen there (`sources.freeze_at_standstill`)."""
    speed = np.where(np.asarray(speed_mps, dtype=float) > 0.3, speed_mps, np.nan)
    ok = (index >= 0) & np.isfinite(speed)
    total = np.bincount(index[ok], weights=speed[ok], minlength=n_bins)[:n_bins]
    count = np.bincount(index[ok], minlength=n_bins)[:n_bins]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / count, np.nan)
    typical = np.nanmedian(mean) if np.isfinite(mean).any() else 15.0
    return np.clip(spacing_m / np.where(np.isfinite(mean), mean, typical), 0.05, 60.0)


def clock_times(index: np.ndarray, time_s: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """Seconds of clock time from each grid point to the next, standstills included: between the
    first samples of neighbouring bins (interpolated over bins without samples), never less than
    the driving time ``dt_s``."""
    n = len(dt_s)
    ok = (index >= 0) & (index < n) & np.isfinite(time_s)
    first = np.full(n, np.inf)
    np.minimum.at(first, index[ok], time_s[ok])
    have = np.isfinite(first)
    if have.sum() < 2:
        return np.asarray(dt_s, dtype=float).copy()
    grid = np.arange(n)
    first = np.interp(grid, grid[have], first[have])
    clock = np.empty(n)
    clock[0] = dt_s[0]
    clock[1:] = np.diff(first)
    return np.fmax(clock, dt_s)


def standstill_bins(index: np.ndarray, speed_mps: np.ndarray, n_bins: int, stop_speed_mps: float = 0.3) -> np.ndarray:
    """True for the grid points where the truck stood still (the speed `sources.freeze_at_standstill`
    calls a standstill)."""
    stopped = (index >= 0) & ~(np.nan_to_num(np.asarray(speed_mps, dtype=float), nan=np.inf) > stop_speed_mps)
    return np.bincount(index[stopped], minlength=n_bins)[:n_bins] > 0


def innovation_log_likelihood(nu: np.ndarray, var: np.ndarray) -> float:
    """Gaussian log-likelihood of a filter's innovations ``nu`` with variances ``var`` (NaN: no
    measurement), -1/2 sum(log S + nu²/S): the data's marginal likelihood under the model."""
    return float(-0.5 * np.nansum(np.log(var) + nu ** 2 / var))


def _robust_var(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    if len(values) < 10:
        return np.nan
    return float(np.median(values ** 2) / CHI2_MEDIAN_1DOF)


def _mean_square(residual: np.ndarray) -> float:
    """Mean square [unit²] with gross outliers beyond 5 robust sigma clipped."""
    robust = _robust_var(residual)
    if not np.isfinite(robust):
        return np.nan
    return float(np.nanmean(np.clip(residual, -5 * np.sqrt(robust), 5 * np.sqrt(robust)) ** 2))


def _residual_var(residual: np.ndarray) -> float:
    """Variance [unit²] a white-noise model must give a residual sequence so that it carries no
    more information than it has: the mean square (gross outliers beyond 5 robust sigma clipped),
    inflated by (1 + rho)/(1 - rho) for its lag-1 autocorrelation rho between neighbouring bins."""
    robust = _robust_var(residual)
    if not np.isfinite(robust):
        return np.nan
    clipped = np.clip(residual, -5 * np.sqrt(robust), 5 * np.sqrt(robust))
    var = float(np.nanmean(clipped ** 2))
    rho = _autocorrelation(clipped, 1)
    rho = float(np.clip(rho, 0.0, 0.9)) if np.isfinite(rho) else 0.0
    return var * (1 + rho) / (1 - rho)


def _count_scale(count: np.ndarray) -> np.ndarray:
    """Variance factor of a bin mean relative to a typical bin: fewer samples, more noise; never
    more than 10x less (neighbouring samples share their noise)."""
    typical = np.median(count[count > 0]) if np.any(count > 0) else 1.0
    with np.errstate(divide="ignore"):
        return np.clip(typical / count, 0.1, 10.0)


def baro_bin_variance(height_bins: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Per-bin barometric variance [m²] from the second differences of the bin heights (a road
    has no curvature a barometer could see over 20 m)."""
    scale = _count_scale(count)
    second = height_bins[2:] - 2 * height_bins[1:-1] + height_bins[:-2]
    weight = scale[2:] + 4 * scale[1:-1] + scale[:-2]
    var = _robust_var(second / np.sqrt(weight))
    var = max(var if np.isfinite(var) else 0.25, 1e-4)
    return var * scale


class GradientSmoother:
    """Runs the Kalman smoother over one drive's measurements with data-estimated noise levels."""

    def __init__(self, measurements: Measurements, settings: SmootherSettings = SmootherSettings()):
        self.m = measurements
        self.s = settings
        self.notes: list[str] = []
        n = len(measurements.dt_s)
        self.r = np.full((n, kalman.N_MEASUREMENTS), np.nan)
        self.dem_sigma_m = 5.0
        self.dem_correlation_m = 300.0
        self.gated = np.zeros(n, bool)
        self.curvature_psd = settings.curvature_psd or 3e-7
        self.offset_psd = settings.offset_psd or 0.0
        self.bias_psd = settings.bias_psd
        self.imu_noise_factor = 1.0
        self.gps_multipath_share: float | None = None
        """The share of the receiver's excess variance taken (`estimate`; None: the stated accuracy)."""
        self.open_sky_m: float | None = None
        self.final_height: tuple[np.ndarray, np.ndarray] | None = None
        """The last run's smoothed height and its variance per grid point."""
        self.offset_steps = np.zeros(n, bool)
        self.bias_drift_sigma_mps2 = 0.0
        self.imu_scale_var = (np.nan_to_num(measurements.imu_scale_var) if measurements.imu_scale_var is not None
                              else np.zeros(n))
        self.scaled = measurements.imu_scale_regressor is not None
        have = np.isfinite(measurements.z).any(axis=0)
        # the bias's rate is a candidate state where an IMU carries the gradient without a barometer;
        # with one, the barometer ties the bias down (on the matrix the likelihood took the rate on
        # one drive of 36, its RMSE moved by 0.0003 %-pt)
        self.rate_possible = (not settings.force_balance and settings.bias_rate_prior_sigma_mps3 > 0
                              and have[kalman.IMU] and not have[kalman.BARO])
        self.bias_rate_psd: float | None = None
        self.rate_model_weight: float | None = None
        """Posterior probability of the model with a bias rate (`_averaged_over_the_rate`)."""

    @property
    def rated(self) -> bool:
        """Whether the IMU bias's rate is a state (`bias_rate_psd` chosen among
        `SmootherSettings.bias_rate_psd_candidates`, None: not)."""
        return self.bias_rate_psd is not None

    @property
    def n_states(self) -> int:
        return (kalman.N_STATES_WITH_SCALE if self.scaled else
                kalman.N_STATES_WITH_BIAS_RATE if self.rated else kalman.N_STATES)

    def _params(self):
        return np.array([self.m.spacing_m, self.curvature_psd, self.s.drift_rate_psd, self.bias_psd,
                         self.dem_sigma_m, self.dem_correlation_m, G_MPS2, self.bias_rate_psd or 0.0])

    def _prior(self, z):
        def first(column):
            finite = np.flatnonzero(np.isfinite(z[:, column]))
            return z[finite[0], column] if len(finite) else np.nan

        baro, dem, gps = first(kalman.BARO), first(kalman.DEM), first(kalman.GPS)
        height = dem if np.isfinite(dem) else gps if np.isfinite(gps) else baro if np.isfinite(baro) else 0.0
        x0 = np.zeros(self.n_states)
        x0[kalman.H] = height
        x0[kalman.DRIFT] = baro - height if np.isfinite(baro) else 0.0
        variances = [100.0 ** 2, 0.1 ** 2, 100.0 ** 2, 0.01 ** 2, self.s.imu_bias_prior_sigma_mps2 ** 2,
                     self.dem_sigma_m ** 2]
        if self.n_states > kalman.BIAS_RATE:
            variances.append(self.s.bias_rate_prior_sigma_mps3 ** 2 if self.rated else 0.0)
        if self.scaled:
            variances.append(max(float(self.m.imu_scale_reset_var[0]), 1e-12))
        return x0, np.diag(variances)

    def run(self, r: np.ndarray, use=(True, True, True, True), backward=True):
        z = self.m.z.copy()
        for column, on in enumerate(use):
            if not on:
                z[:, column] = np.nan
        x0, p0 = self._prior(z)
        clock = self.m.clock_s if self.rated else None
        return kalman.smooth(z, r, self.m.dt_s, self._steps(), self._params(), x0, p0, backward,
                             self.m.imu_scale_regressor, clock)

    def _steps(self):
        """Extra process variance per grid point: the barometric offset's random walk while
        driving (offset_psd dt), and its step at a standstill on the way into the grid point
        after the standstill's."""
        n = len(self.m.dt_s)
        step = np.zeros((n, self.n_states))
        step[:, kalman.DRIFT] = self.offset_psd * self.m.dt_s
        if self.scaled:
            step[1:, kalman.SCALE] = self.m.imu_scale_reset_var[1:]
        if self.m.stopped is not None:
            after = np.zeros(n, bool)
            after[1:] = self.m.stopped[:-1]
            step[after, kalman.DRIFT] = self.s.stop_offset_sigma_m ** 2
        step[self.offset_steps, kalman.DRIFT] += self.s.offset_step_sigma_m ** 2
        return step

    def estimate(self) -> SmootherResult:
        """The smoothed profile; with `SmootherSettings.gps_multipath_share` estimated again from the
        start with GPS altitude's variance above the receiver's open-sky level scaled by the share
        of it the first estimate's residual shows (`gps_altitude.multipath_share`: one
        expectation-maximisation step from the stated accuracy), so that the noise levels, the
        curvature and the map's model are chosen with it."""
        result = self._estimate()
        m = self.m
        if not (self.s.gps_multipath_share and np.isfinite(m.z[:, kalman.GPS]).any()):
            return result
        open_sky = gps_altitude.open_sky_accuracy_m(m.v_acc_m, m.spacing_m)
        height, height_var = self.final_height
        share = gps_altitude.multipath_share(m.z[:, kalman.GPS] - height, height_var, m.v_acc_m, open_sky)
        if share is None:
            return result
        again = GradientSmoother(m, self.s)
        again.open_sky_m, again.gps_multipath_share = open_sky, share
        result = again._estimate()
        result.notes.append(f"GPS altitude: of the receiver's stated variance above its open-sky {open_sky:.1f} m "
                            f"(multipath in towns) its residual shows {share:.2f}; taken so")
        return result

    def _estimate(self) -> SmootherResult:
        m, s = self.m, self.s
        z, count = m.z, m.count
        have = np.isfinite(z).any(axis=0)
        r = self.r
        if have[kalman.BARO]:
            r[:, kalman.BARO] = baro_bin_variance(z[:, kalman.BARO], count[:, kalman.BARO])
        imu_scale = _count_scale(count[:, kalman.IMU])
        if have[kalman.IMU]:
            r[:, kalman.IMU] = 0.5 ** 2 * imu_scale
        if have[kalman.GPS]:
            r[:, kalman.GPS] = gps_altitude.altitude_variance_m2(
                m.v_acc_m, s.gps_sigma_factor, self.open_sky_m,
                1.0 if self.gps_multipath_share is None else self.gps_multipath_share)
        # the road's curvature PSD first (needs no IMU noise level), then pass 1 without the map:
        # the reference the map is checked against, and the IMU's noise from its residual
        reference = None
        imu_led = have[kalman.IMU] and not have[kalman.BARO] and (
            have[kalman.GPS] or s.imu_bias_prior_sigma_mps2 <= KNOWN_BIAS_MPS2)
        if imu_led and s.force_balance and have[kalman.GPS]:
            self._differenced_noise(r, imu_scale)
            across = self._curvature_across_force_gaps(r) if s.curvature_psd is None else None
            if across is None:
                self._noise_by_likelihood(r, have, ("curvature_psd", "imu_noise_factor"))
            else:
                self.curvature_psd = across
                self._noise_by_likelihood(r, have, ("imu_noise_factor",))
            x, _, _, _ = self.run(r, use=(True, False, True, True))
            reference = x[:, kalman.H]
        elif imu_led:
            self._imu_led_noise(r, imu_scale)
            self._noise_by_likelihood(r, have, IMU_LED_AXES)
            x, _, _, _ = self.run(r, use=(True, False, True, True))
            reference = x[:, kalman.H]
            if have[kalman.GPS]:
                self.bias_drift_sigma_mps2 = self._bias_drift_between_blocks(r, x[:, kalman.BIAS])
        elif have[kalman.BARO] or have[kalman.IMU]:
            # GPS altitude alone is no check of the map: its errors, in the residual, made the
            # map's estimated error large and gated out stretches where the map was the better
            # source (measured: gps+can regional 0.64 -> 0.78 %-pt)
            if s.curvature_psd is None:
                self.curvature_psd = (self._curvature_by_imu(r, imu_scale) if have[kalman.IMU] and
                                      (have[kalman.BARO] or have[kalman.GPS]) else self._most_likely_curvature(r))
            x, _, _, _ = self.run(r, use=(True, False, True, True))
            if have[kalman.IMU]:
                gamma = x[:, kalman.GAMMA]
                residual = z[:, kalman.IMU] - _gravity_along_road_mps2(gamma) - x[:, kalman.BIAS]
                var = _residual_var(residual / np.sqrt(imu_scale))
                if np.isfinite(var):
                    r[:, kalman.IMU] = max(var, 1e-6) * imu_scale
            if self._noise_by_likelihood(r, have):
                x, _, _, _ = self.run(r, use=(True, False, True, True))
            if have[kalman.BARO] and have[kalman.IMU] and self._offset_steps(r):
                self._noise_by_likelihood(r, have)
                x, _, _, _ = self.run(r, use=(True, False, True, True))
            reference = x[:, kalman.H] if (have[kalman.BARO] or have[kalman.GPS]) else None
        elif have[kalman.GPS] and s.curvature_psd is None:
            self.curvature_psd = self._most_likely_curvature(r)
        if have[kalman.DEM]:
            self._dem_model(reference)
            if reference is not None and not have[kalman.BARO]:
                self.notes.append(dem_unchecked_note(self.dem_sigma_m, self.dem_correlation_m, have[kalman.IMU]))
            white = max(s.dem_white_fraction * self.dem_sigma_m, 0.5)
            h_acc = np.nan_to_num(m.h_acc_m, nan=10.0)
            r[:, kalman.DEM] = np.where(self.gated, np.nan, white ** 2 + (s.terrain_cross_slope * h_acc) ** 2)
        x, p, nu, var = self.run(r)
        self.final_height = (x[:, kalman.H], p[:, kalman.H, kalman.H])
        shared = self._bias_shared_std(r, p) if have[kalman.IMU] and not self.scaled else None
        if self.rate_possible:
            x, p = self._averaged_over_the_rate(r, x, p, innovation_log_likelihood(nu, var))
            if 0.05 < self.rate_model_weight < 0.95:
                self.notes.append(f"no barometer: the log does not tell whether the IMU's bias drifts (warm-up): a "
                                  f"rate state is {100 * self.rate_model_weight:.0f} % likely; height, gradient and "
                                  f"bias are averaged over both models, their σ holds both")
        if self.rated:
            moved = x[-1, kalman.BIAS] - x[0, kalman.BIAS]
            self.notes.append(f"no barometer: the IMU's bias follows a drift (warm-up) as a rate state, by "
                              f"{moved:+.3f} m/s² over the drive (rate {60e3 * x[0, kalman.BIAS_RATE]:+.2f} mm/s² "
                              f"per minute at the start, {60e3 * x[-1, kalman.BIAS_RATE]:+.2f} at the end)")
        weights = self._weights(r, p, have)
        posterior = None
        if not have[kalman.IMU]:
            posterior = (self._smoother_gains(r), np.ascontiguousarray(p[:, :, kalman.GAMMA]))
        ramp = self._standstill_ramp_sigma(x[:, kalman.BIAS]) if self.rate_possible else 0.0
        # the bias's drift that the near-constant bias state does not follow (between blocks, and
        # over the standstills), in the share of the gradient the accelerometer carries
        drift = np.hypot(self.bias_drift_sigma_mps2, ramp) / G_MPS2 * weights["imu"]
        return SmootherResult(
            height_m=x[:, kalman.H], gradient=x[:, kalman.GAMMA],
            gradient_std=np.sqrt(p[:, kalman.GAMMA, kalman.GAMMA] + drift ** 2),
            drift_m=x[:, kalman.DRIFT], imu_bias_mps2=x[:, kalman.BIAS],
            imu_bias_std_mps2=np.sqrt(p[:, kalman.BIAS, kalman.BIAS]),
            imu_scale=x[:, kalman.SCALE] if self.scaled else None,
            imu_scale_std=np.sqrt(p[:, kalman.SCALE, kalman.SCALE]) if self.scaled else None,
            dem_error_m=x[:, kalman.DEM_ERROR],
            map_gated=self.gated.copy(), weights=weights,
            noise={"curvature_psd": self.curvature_psd, "offset_psd": self.offset_psd if have[kalman.BARO] else None,
                   "bias_psd": self.bias_psd if have[kalman.IMU] else None,
                   "baro_sigma_m": float(np.sqrt(np.nanmedian(r[:, kalman.BARO]))) if have[kalman.BARO] else None,
                   "imu_sigma_mps2": (float(np.sqrt(np.nanmedian(r[np.isfinite(z[:, kalman.IMU]), kalman.IMU])))
                                      if have[kalman.IMU] else None),
                   "dem_sigma_m": self.dem_sigma_m if have[kalman.DEM] else None,
                   "dem_correlation_m": self.dem_correlation_m if have[kalman.DEM] else None},
            notes=self.notes, imu_bias_ramp_std_mps2=ramp,
            imu_bias_shared_std_mps2=(None if shared is None else
                                      np.clip(shared, -np.sqrt(p[:, kalman.BIAS, kalman.BIAS]),
                                              np.sqrt(p[:, kalman.BIAS, kalman.BIAS]))),
            gradient_posterior=posterior)

    def _smoother_gains(self, r) -> np.ndarray:
        """The RTS smoother's gains of this model with measurement variances ``r``
        (`kalman.smoother_gains`, from a forward pass): its smoothed errors' cross-covariances."""
        _, p_filt, _, _ = self.run(r, backward=False)
        clock = self.m.clock_s if self.rated else None
        return kalman.smoother_gains(p_filt, self.m.dt_s, self._steps(), self._params(), clock)

    def _bias_shared_std(self, r, p_smooth) -> np.ndarray:
        """Per grid point, how much [m/s², signed] of the bias's error it shares with the drive:
        its smoothed covariance with the error of the bias averaged over the drive, over that
        mean's σ (one factor: e_i = l_i ē/σ(ē) + own_i, l_i = Cov(e_i, ē)/σ(ē)). The bias walks
        (``bias_psd``, and its rate), so the smoother's error of it at two stretches apart is not
        one error: with a barometer the walk trades with the barometer's drift and the gradient
        over minutes, and the errors before and after a stop differ (the matrix's long-haul
        `typical` seed 5: +4 and −2.5 mm/s² against a stated 2.4). A weighing of one stretch
        corrects the shared part of another's, not its own (`mass.calibration`). ``p_smooth``
        are this model's smoothed covariances."""
        with_mean = kalman.covariance_with_mean(self._smoother_gains(r), p_smooth, kalman.BIAS)
        mean_var = float(np.mean(with_mean))
        return with_mean / np.sqrt(mean_var) if mean_var > 0 else np.zeros(len(with_mean))

    def _standstill_ramp_sigma(self, bias_mps2) -> float:
        """1-sigma [m/s²] of the IMU bias's departure from ``bias_mps2``, this smoother's, as the
        standstills show it: standing, the log measures how far the bias moved
        (`Measurements.standstill_bias_changes`), and the smoother's bias should have moved as far
        between the grid points either side of the standstill's. Without a barometer its bias
        state follows a cab's warm-up only as its near-constant walk or its rate allow, and the
        drift between blocks (`_bias_drift_between_blocks`) does not tell that from GPS altitude's
        correlated error (the matrix's long-haul `harsh` seed 5: the bias moved 0.016 m/s² over
        its 10-minute stop, the smoother's by 0.007 at the standstill, the drift between blocks 0, the
        stated sigma 0.0014 against an error of 0.009 after the stop). The move is taken at the
        standstill's edges, over the same clock time as the log's change: means over
        ``bias_block_s`` of driving either side held the warm-up while driving as well, which the
        log's change does not (held-out long-haul `typical` seed 6: the log's change 8.5 mm/s², the
        smoother's 5.5 at the edges and 8.9 between the blocks' means, its error after the stop
        −4 mm/s²). The largest difference over the drive's standstills, less the change's own
        noise, as one error of each stretch between stops: the difference of two stretches'
        errors bounds neither alone."""
        worst = 0.0
        last = len(bias_mps2) - 1
        for k, change, variance in self.m.standstill_bias_changes:
            if 0 < k < last:
                moved = bias_mps2[k + 1] - bias_mps2[k - 1]
                worst = max(worst, (moved - change) ** 2 - variance)
        sigma = float(np.sqrt(worst))
        if sigma > 0:
            self.notes.append(f"no barometer: the IMU's bias moved over a standstill by {sigma:.4f} m/s² more or less "
                              f"than the smoother's (imu_bias_ramp_std_mps2, in the gradient's and the mass's uncertainty)")
        return sigma

    def _offset_steps(self, r) -> bool:
        """Where the barometer's forward innovation fails a chi-square test against the
        accelerometer-carried prediction (false alarm ``offset_step_probability`` per grid point),
        the offset gets a step of ``offset_step_sigma_m`` on the way into that point and the two
        after it (the cab's pressure follows its ventilation with a lag of seconds). A ventilation
        change while driving is a step of the offset, which its slow random walk cannot follow: it
        went into the road height (matrix urban harsh seed 1: +1.5 m within three bins on a 4.5 %
        descent gave +5 %-pt). Repeated ``offset_step_rounds`` times; returns whether any was found."""
        limit = chi2.ppf(1 - self.s.offset_step_probability, 1)
        n = len(self.offset_steps)
        found = False
        for _ in range(self.s.offset_step_rounds):
            _, _, nu, var = self.run(r, use=(True, False, True, True), backward=False)
            with np.errstate(invalid="ignore"):
                failed = np.nan_to_num(nu[:, kalman.BARO] ** 2 / var[:, kalman.BARO]) > limit
            failed &= ~self.offset_steps
            if not failed.any():
                break
            for lag in range(3):
                index = np.flatnonzero(failed) + lag
                self.offset_steps[index[index < n]] = True
            found = True
        if found:
            runs = int(np.sum(np.diff(np.concatenate([[0], self.offset_steps.astype(int)])) == 1))
            self.notes.append(f"barometer: {runs} step(s) of its offset while driving (cab ventilation) found by "
                              f"its innovations and left to the other sources")
        return found

    def _curvature_by_imu(self, r, imu_scale):
        """The curvature PSD whose barometer/GPS-only gradient best predicts the accelerometer:
        the mean square of a_imu - dv/dt - g sin(gamma), high-passed over 2 km (the slow bias),
        is the IMU's noise plus g² times the gradient's mean square error, since the two are
        independent; searched upwards from the smallest candidate until it grows again."""
        z = self.m.z[:, kalman.IMU]
        ok = np.isfinite(z)
        grid = np.arange(len(z))
        window = max(3, int(self.s.gate_detrend_m / self.m.spacing_m) | 1)
        best, best_score = self.curvature_psd, np.inf
        for candidate in self.s.curvature_candidates:
            self.curvature_psd = candidate
            x, _, _, _ = self.run(r, use=(True, False, False, True))
            gamma = x[:, kalman.GAMMA]
            residual = z - _gravity_along_road_mps2(gamma)
            filled = np.interp(grid, grid[ok], residual[ok])
            high = residual - uniform_filter1d(filled, window, mode="nearest")
            score = float(np.sum((high[ok] ** 2) / imu_scale[ok]) / np.sum(1 / imu_scale[ok]))
            if score >= best_score:
                break
            best, best_score = candidate, score
        return best

    def _differenced_noise(self, r, imu_scale):
        """The force balance's noise per bin from its neighbouring bins' differences (the road's
        gradient changes by far less over 10 m than the force balance scatters), with the
        count scaling of the bins. Measured on the matrix's urban typical drive with the true
        mass: 0.018 m/s² from the differences, 0.024 against the true gradient; the IMU-led EM
        gave 0.17: between the force balance's gaps (braking, coasting) the profile follows GPS
        altitude, whose gradient error then looks like the force balance's noise, and each EM step
        trusts it less."""
        z = self.m.z[:, kalman.IMU]
        difference = np.diff(z) / np.sqrt(imu_scale[1:] + imu_scale[:-1])
        var = _mean_square(difference)
        if not np.isfinite(var):
            var = self.s.imu_led_start_sigma_mps2 ** 2
        r[:, kalman.IMU] = max(var, 1e-6) * imu_scale + self.imu_scale_var
        self.imu_noise_factor = 1.0
        self.notes.append(f"no barometer and no IMU: the force balance carries the gradient (noise "
                          f"{np.sqrt(max(var, 1e-6)):.3f} m/s² per bin from its own differences, times a factor "
                          f"chosen by likelihood), its bias tied to GPS altitude")

    def _curvature_across_force_gaps(self, r) -> float | None:
        """The curvature PSD whose profile best predicts the force balance across gaps like its
        own: where the force balance has no sample (braking, coasting) the gradient is the
        curvature prior's interpolation between its samples, GPS altitude's and the map's, so
        the prior is chosen by how well it interpolates. The drive's own gaps, moved forwards and
        backwards by twice their length-weighted length (Σl²/Σl bins), hide force-balance
        samples in stretches of the same lengths a gap's length clear of the real gaps (the
        windows next to a brake reading read high by the brake's unseen impulse, `force_gaps`;
        hidden right beside the gaps, urban `typical` seed 6 took 3e-5 and 0.97 %-pt). Per
        candidate the map-free smoother runs without them, each direction apart; the score is
        the hidden samples' mean square residual (force balance minus e^k (g sin γ + u) − u + b;
        its noise is the same for every candidate), the least taken. None with fewer than
        `MIN_HIDDEN_SAMPLES` hidden samples a direction or no gap: the likelihood chooses. The
        likelihood of the innovations sees the road's smoothness from bin to bin, not its change
        over a braking stretch: it took 3e-6 on the matrix's urban drives, whose streets change
        by 5e-6 to 1.3e-5 /m over their gaps, and the gradient's error sat in the gaps."""
        z = self.m.z[:, kalman.IMU]
        measured = np.isfinite(z)
        inside = np.flatnonzero(measured)
        if len(inside) < 2:
            return None
        gap = np.zeros(len(z), bool)
        gap[inside[0]:inside[-1] + 1] = ~measured[inside[0]:inside[-1] + 1]
        gaps = np.array([end - start for start, end in true_runs(gap)])
        if len(gaps) == 0:
            return None
        length = max(int(round(np.sum(gaps ** 2) / np.sum(gaps))), 1)
        shift = 2 * length
        if shift >= len(z):
            return None
        # the gaps moved forwards and backwards by twice their length: stretches of their lengths a
        # gap's length clear of them, each direction run apart
        folds = [np.concatenate([np.zeros(shift, bool), gap[:-shift]]) & measured,
                 np.concatenate([gap[shift:], np.zeros(shift, bool)]) & measured]
        if min(fold.sum() for fold in folds) < MIN_HIDDEN_SAMPLES:
            return None
        u = (np.nan_to_num(self.m.imu_scale_regressor) if self.m.imu_scale_regressor is not None
             else np.zeros(len(z)))
        best, best_score = None, np.inf
        for candidate in self.s.curvature_candidates:
            self.curvature_psd = candidate
            square, count = 0.0, 0
            for hidden in folds:
                held = r.copy()
                held[hidden, kalman.IMU] = np.nan
                x, _, _, _ = self.run(held, use=(True, False, True, True))
                gamma = x[:, kalman.GAMMA]
                scale = np.exp(x[:, kalman.SCALE]) if self.scaled else 1.0
                predicted = scale * (_gravity_along_road_mps2(gamma) + u) - u + x[:, kalman.BIAS]
                square += float(np.sum((z[hidden] - predicted[hidden]) ** 2))
                count += int(hidden.sum())
            if square / count < best_score:
                best, best_score = candidate, square / count
        self.notes.append(f"no barometer and no IMU: the road's curvature {best:.0e} /m, the one whose profile best "
                          f"predicts the force balance where gaps like its own ({length * self.m.spacing_m:.0f} m) "
                          f"hide it")
        return best

    def _imu_led_noise(self, r, imu_scale):
        """Without a barometer the accelerometer carries the gradient and GPS altitude ties its
        bias down over long baselines. Its noise cannot be taken from the residual against a
        GPS-led reference (that holds the GPS gradient's error, ten times the IMU's noise), so
        it is estimated with the profile: expectation-maximisation of the IMU variance (the
        smoothed residual's mean square plus the smoother's own variance of g sin(gamma) + b),
        started below any plausible IMU noise so that it climbs to the nearest fixed point,
        per curvature candidate, searched upwards until the likelihood of the map-free innovations
        falls, the pair with the largest likelihood is kept."""
        z = self.m.z[:, kalman.IMU]
        best, best_ll, best_r = None, -np.inf, None
        candidates = ((self.s.curvature_psd,) if self.s.curvature_psd is not None
                      else self.s.curvature_candidates)
        for candidate in candidates:
            self.curvature_psd = candidate
            trial = r.copy()
            var = self.s.imu_led_start_sigma_mps2 ** 2
            for _ in range(self.s.imu_led_iterations):
                trial[:, kalman.IMU] = var * imu_scale
                x, p, _, _ = self.run(trial, use=(True, False, True, True))
                gamma = x[:, kalman.GAMMA]
                residual = (z - _gravity_along_road_mps2(gamma) - x[:, kalman.BIAS]) / np.sqrt(imu_scale)
                spread = G_MPS2 ** 2 * (p[:, kalman.GAMMA, kalman.GAMMA] + p[:, kalman.BIAS, kalman.BIAS]
                                        + 2 * p[:, kalman.GAMMA, kalman.BIAS]) / imu_scale
                new = _mean_square(residual) + float(np.nanmean(np.where(np.isfinite(z), spread, np.nan)))
                if not np.isfinite(new):
                    break
                converged = abs(new / var - 1) < 0.02
                var = max(new, 1e-6)
                if converged:
                    break
            trial[:, kalman.IMU] = var * imu_scale
            _, _, nu, innovation_var = self.run(trial, use=(True, False, True, True), backward=False)
            ll = -0.5 * np.nansum(np.log(innovation_var) + nu ** 2 / innovation_var)
            if ll <= best_ll:
                break
            best, best_ll, best_r = candidate, ll, trial[:, kalman.IMU].copy()
        self.curvature_psd = best
        r[:, kalman.IMU] = best_r
        tied = "tied to GPS altitude" if np.isfinite(self.m.z[:, kalman.GPS]).any() else "known beforehand"
        noise = float(np.sqrt(np.nanmedian(best_r)))
        self.notes.append(f"no barometer: the IMU carries the gradient (noise {noise:.3f} m/s² "
                          f"per bin, estimated with the profile), its bias and mounting pitch {tied}")

    def _bias_drift_between_blocks(self, r, bias_mps2) -> float:
        """How far [m/s², 1-sigma] the accelerometer's bias moves away from the bias the IMU-led
        smoother keeps: near-constant (its walk stays at the floor: without a barometer the
        likelihood cannot choose it, and a walk fitted to follow a cab's warm-up, 0.1-0.2 m/s² in
        half an hour, let the bias trade with the gradient: the matrix's no-baro typical p95 0.108
        -> 0.169 %-pt), or a ramp where the likelihood took the bias's rate as a state. The blocks
        run with the same model, so with the rate they tell only the drift beyond its ramp (on the
        matrix one drive of 24 at typical and harsh, 0.009 m/s²: nothing counted twice).
        The bias is estimated in each block of ``bias_block_s`` of driving on its own (the IMU only
        there, GPS altitude there and over a block's length on either side); the mean square of its
        differences from the whole drive's bias, less the blocks' own error, is the drift's variance
        (zero if negative). The blocks' own error is the smoother's variance or, if larger, what
        the two halves of each block disagree by: GPS altitude's errors are correlated over a
        block, which its variance does not see (on three of the matrix's harsh drives 0.011-0.023
        m/s² against a stated 0.003-0.006)."""
        elapsed = np.cumsum(self.m.dt_s)
        halves = np.floor(2 * elapsed / self.s.bias_block_s).astype(int)
        z = self.m.z

        def block_bias(inside):
            if np.sum(np.isfinite(z[inside, kalman.IMU])) < 10 or np.sum(np.isfinite(z[inside, kalman.GPS])) < 10:
                return np.nan, np.nan
            index = np.flatnonzero(inside)
            margin = len(index)
            window = slice(max(index[0] - margin, 0), min(index[-1] + 1 + margin, len(inside)))
            trial = r[window].copy()
            trial[~inside[window], kalman.IMU] = np.nan
            x, p = self._run_on(window, trial)
            there = inside[window]
            return float(np.mean(x[there, kalman.BIAS])), float(np.mean(p[there, kalman.BIAS, kalman.BIAS]))

        square, variance, halves_square = [], [], []
        for j in range(halves.max() // 2 + 1):
            inside = halves // 2 == j
            bias, var = block_bias(inside)
            first, _ = block_bias(halves == 2 * j)
            second, _ = block_bias(halves == 2 * j + 1)
            if not np.isfinite([bias, var, first, second]).all():
                continue
            square.append((bias - np.mean(bias_mps2[inside])) ** 2)
            variance.append(var)
            halves_square.append((first - second) ** 2 / 4)
        if len(square) < self.s.bias_min_blocks:
            return 0.0
        noise = max(np.mean(variance), np.mean(halves_square))
        drift = float(np.sqrt(max(np.mean(square) - noise, 0.0)))
        if drift > 0:
            self.notes.append(f"no barometer: the IMU's bias moves by {drift:.3f} m/s² (1 sigma) between "
                              f"{self.s.bias_block_s / 60:.0f}-minute blocks beyond their own error (warm-up); "
                              f"in the gradient's sigma where the IMU carries it")
        return drift

    def _run_on(self, part: slice, r):
        """The map-free smoother over the grid points ``part`` alone (``r`` its variances there), with
        this drive's noise levels: the cost of a block, not of the drive."""
        block = GradientSmoother(self.m.part(part), self.s)
        block.curvature_psd, block.bias_psd, block.bias_rate_psd = self.curvature_psd, self.bias_psd, self.bias_rate_psd
        block.dem_sigma_m, block.dem_correlation_m = self.dem_sigma_m, self.dem_correlation_m
        x, p, _, _ = block.run(r, use=(True, False, True, True))
        return x, p

    def _averaged_over_the_rate(self, r, x, p, ll_kept):
        """Height, gradient and the IMU's bias averaged over the two models of the bias: without a
        rate and with one (the rate the likelihood-ratio test took, else a constant one), weighted by their
        marginal likelihoods (the forward innovations' likelihood integrates the rate's prior) at
        even prior odds: a cold IMU warms up on every start, a warm one does not, and the log
        does not say which. The test keeps the simpler model unless the data insist; where GPS
        altitude cannot tell a ramp from its own correlated error (likelihoods within a few units)
        the model it kept stated a σ that held neither the warm-up it missed nor the other model's
        estimate (long-haul `typical` seed 2 of the matrix: 85 % of the bins inside ±2σ). The bias
        goes to the mass's accelerometer regressor, which needs the same answer. ``x``, ``p`` and
        ``ll_kept`` are the kept model's run and its log-likelihood; returns them with the mixture's
        mean and variance in the height, gradient and bias."""
        kept = self.bias_rate_psd
        self.bias_rate_psd = 0.0 if kept is None else None
        x_other, p_other, nu, var = self.run(r)
        ll_other = innovation_log_likelihood(nu, var)
        self.bias_rate_psd = kept
        weight = 1.0 / (1.0 + np.exp(np.clip(ll_kept - ll_other, -700.0, 700.0)))
        self.rate_model_weight = weight if kept is None else 1.0 - weight
        x, p = x.copy(), p.copy()
        for state in (kalman.H, kalman.GAMMA, kalman.BIAS):
            mean = (1.0 - weight) * x[:, state] + weight * x_other[:, state]
            p[:, state, state] = ((1.0 - weight) * (p[:, state, state] + (x[:, state] - mean) ** 2)
                                  + weight * (p_other[:, state, state] + (x_other[:, state] - mean) ** 2))
            x[:, state] = mean
        return x, p

    def _noise_by_likelihood(self, r, have, names=("curvature_psd", "offset_psd", "bias_psd", "imu_noise_factor")) -> bool:
        """Maximum likelihood of the map-free innovations (barometer, IMU, GPS) over the noise
        levels the data cannot give one at a time, by coordinate ascent over candidate grids: the
        road's curvature PSD, the barometric offset's random walk while driving, the IMU bias's
        walk and a factor on the IMU noise. Each was chosen on its own before (curvature by the
        IMU's prediction error, IMU noise from its residual, the walks fixed at 0 and 1e-8); the
        three interact: an unmodelled cab-pressure change while driving went into the height, made
        the IMU look noisy against it and the road stiffer than it is, and the stated sigma was
        several times too small (harsh: 72 % of the bins inside ±2σ). The IMU bias's rate
        (`kalman.BIAS_RATE`), where it may be a state, is one more axis, whose candidates are
        nested models in the order given: a later one is taken only where it passes a likelihood
        ratio test (`SmootherSettings.bias_rate_probability`). Returns whether anything changed."""
        axes = []
        if self.s.curvature_psd is None:
            axes.append(("curvature_psd", self.s.curvature_candidates))
        if have[kalman.BARO] and self.s.offset_psd is None:
            axes.append(("offset_psd", self.s.offset_psd_candidates))
        if have[kalman.IMU] and self.s.bias_psd_candidates:
            axes.append(("bias_psd", tuple(c for c in self.s.bias_psd_candidates if c >= self.s.bias_psd)))
            axes.append(("imu_noise_factor", self.s.force_balance_noise_factors if self.s.force_balance
                          else self.s.imu_noise_factors))
        if self.rate_possible:
            axes.append(("bias_rate_psd", self.s.bias_rate_psd_candidates))
        axes = [(name, candidates) for name, candidates in axes if name in names]
        if not axes:
            return False
        # the factors are on the noise estimated from the residual, not on an earlier call's choice
        imu = (r[:, kalman.IMU] - self.imu_scale_var) / self.imu_noise_factor
        use = (True, False, True, True)

        def likelihood():
            r[:, kalman.IMU] = imu * self.imu_noise_factor + self.imu_scale_var
            _, _, nu, var = self.run(r, use=use, backward=False)
            return innovation_log_likelihood(nu, var)

        rate_gain = chi2.ppf(1 - self.s.bias_rate_probability, 1) / 2
        start = {name: getattr(self, name) for name, _ in axes}
        best_ll = likelihood()
        for _ in range(self.s.likelihood_rounds):
            moved = False
            for name, candidates in axes:
                for candidate in candidates:
                    if candidate == getattr(self, name):
                        continue
                    kept = getattr(self, name)
                    setattr(self, name, candidate)
                    ll = likelihood()
                    nested = name == "bias_rate_psd" and candidates.index(candidate) > candidates.index(kept)
                    gain = rate_gain if nested else 1e-6
                    if ll > best_ll + gain:
                        best_ll, moved = ll, True
                    else:
                        setattr(self, name, kept)
            if not moved:
                break
        r[:, kalman.IMU] = imu * self.imu_noise_factor + self.imu_scale_var
        return any(getattr(self, name) != value for name, value in start.items())

    def _most_likely_curvature(self, r):
        """The curvature PSD among the candidates with the largest likelihood of the map-free
        innovations (Gaussian: -1/2 sum(log S + nu²/S))."""
        best, best_ll = self.curvature_psd, -np.inf
        for candidate in self.s.curvature_candidates:
            self.curvature_psd = candidate
            _, _, nu, var = self.run(r, use=(True, False, True, True), backward=False)
            ll = innovation_log_likelihood(nu, var)
            if ll > best_ll:
                best, best_ll = candidate, ll
        return best

    def _dem_model(self, reference):
        """DEM error size and correlation length from its residual against the map-free profile,
        and the gate: windows where the residual is too large for that error model."""
        m, s = self.m, self.s
        dem = m.z[:, kalman.DEM]
        if reference is None:
            self.notes.append(f"map not checked against barometer/IMU (neither present): taken as it is, its error "
                              f"assumed {self.dem_sigma_m:.0f} m over {self.dem_correlation_m:.0f} m")
            return
        residual = dem - reference
        ok = np.isfinite(residual)
        if ok.sum() < 50:
            return
        grid = np.arange(len(residual))
        filled = np.interp(grid, grid[ok], residual[ok])
        window = max(3, int(s.gate_detrend_m / m.spacing_m) | 1)
        high = np.where(ok, filled - median_filter(filled, size=window, mode="nearest"), np.nan)
        sigma = np.sqrt(_robust_var(high - np.nanmedian(high)))
        standardised = high / sigma
        inlier = np.where(np.abs(standardised) < 3, high, np.nan)
        length = _correlation_length_bins(inlier, max_lag=int(3000 / m.spacing_m))
        if np.isfinite(length):
            self.dem_correlation_m = float(np.clip(length * m.spacing_m, 50.0, 3000.0))
        self.dem_sigma_m = float(np.clip(sigma, 0.5, 50.0))
        bins = max(3, int(round(2 * self.dem_correlation_m / m.spacing_m)))
        phi = np.exp(-m.spacing_m / self.dem_correlation_m)
        dof = max(1.0, bins * (1 - phi ** 2) / (1 + phi ** 2))
        limit = chi2.ppf(1 - s.gate_probability, dof) / dof
        square = np.where(ok, np.minimum(standardised ** 2, 100.0), 0.0)
        support = uniform_filter1d(ok.astype(float), bins, mode="constant")
        with np.errstate(invalid="ignore", divide="ignore"):
            statistic = uniform_filter1d(square, bins, mode="constant") / support
        flagged = np.nan_to_num(statistic) > limit
        self.gated = uniform_filter1d(flagged.astype(float), bins, mode="constant") > 0
        if self.gated.any():
            runs = int(np.sum(np.diff(np.concatenate([[0], self.gated.astype(int)])) == 1))
            self.notes.append(f"map gated out on {self.gated.sum() * m.spacing_m / 1000:.2f} km in {runs} stretch(es) "
                              f"where it disagrees with barometer/IMU beyond its error model "
                              f"(sigma {self.dem_sigma_m:.1f} m, correlation {self.dem_correlation_m:.0f} m)")

    def _weights(self, r, p_full, have):
        """Each source's share of the information on the gradient per grid point: how much the
        gradient's variance grows without it, normalised over the sources."""
        information = {}
        base = 1.0 / p_full[:, kalman.GAMMA, kalman.GAMMA]
        for column, name in enumerate(SOURCE_NAMES):
            if not have[column] or np.all(np.isnan(r[:, column])):
                information[name] = np.zeros(len(base))
                continue
            use = tuple(c != column for c in range(kalman.N_MEASUREMENTS))
            _, p, _, _ = self.run(r, use=use)
            information[name] = np.clip(base - 1.0 / p[:, kalman.GAMMA, kalman.GAMMA], 0, None)
        total = sum(information.values())
        with np.errstate(invalid="ignore", divide="ignore"):
            return {name: np.where(total > 0, info / total, 0.0) for name, info in information.items()}


def _gravity_along_road_mps2(gamma):
    """What gravity adds to a level-mounted accelerometer on a road of gradient ``gamma`` (tan α):
    g sin α [m/s²], the accelerometer channel's measurement model (`kalman`)."""
    return G_MPS2 * gamma / np.sqrt(1 + gamma ** 2)


def dem_unchecked_note(sigma_m: float, correlation_m: float, imu: bool) -> str:
    """How far the map may be off where no barometer checks it: its residual against GPS altitude
    (and the IMU) holds the GPS's own error too, so its size sigma is an upper bound of the DEM's,
    and a height error field of sigma over a correlation length L moves the gradient over L by
    sqrt(2 (1 - 1/e)) sigma / L."""
    gradient_pct = 100 * np.sqrt(2 * (1 - np.exp(-1))) * sigma_m / correlation_m
    against = "GPS altitude and the IMU" if imu else "GPS altitude"
    return (f"no barometer: the map is checked against {against} only; where it is not gated out it may be off "
            f"by up to {sigma_m:.1f} m in height and {gradient_pct:.2f} %-points in gradient over "
            f"{correlation_m:.0f} m")


def _autocorrelation(values: np.ndarray, lag: int) -> float:
    a, b = values[:-lag], values[lag:]
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 20:
        return np.nan
    a, b = a[ok] - np.mean(a[ok]), b[ok] - np.mean(b[ok])
    return float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)))


def _correlation_length_bins(values: np.ndarray, max_lag: int) -> float:
    """First lag [bins] where the autocorrelation of a gappy series falls below 1/e (linearly
    interpolated); NaN if it never does within ``max_lag``."""
    ok = np.isfinite(values)
    if ok.sum() < 50:
        return np.nan
    x = np.where(ok, values - np.mean(values[ok]), 0.0)
    mask = ok.astype(float)
    size = 1 << int(np.ceil(np.log2(2 * len(x))))
    fx, fm = np.fft.rfft(x, size), np.fft.rfft(mask, size)
    product = np.fft.irfft(fx * np.conj(fx), size)[:max_lag + 1]
    pairs = np.fft.irfft(fm * np.conj(fm), size)[:max_lag + 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        acf = (product / np.maximum(pairs, 1.0)) / (product[0] / max(pairs[0], 1.0))
    below = np.flatnonzero(acf < np.exp(-1))
    if len(below) == 0:
        return np.nan
    k = below[0]
    return float(k - 1 + (acf[k - 1] - np.exp(-1)) / (acf[k - 1] - acf[k])) if k > 0 else 0.5
