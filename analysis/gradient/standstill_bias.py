"""The accelerometer's bias steps at standstills, measured where the truck stands.

A truck standing on one spot reads g sin(road angle + mounting pitch) + bias along its
accelerometer's x axis; the road under its wheels does not change while it stands, so what the
reading changes by from the start of a long standstill to its end is what the bias changed by: the
IMU warming with the cab, the tractor's pitch on its springs under a new trailer or load. The
smoother's bias is a random walk over driving time (`kalman`): a standstill is one grid point, and
a step there is split between the stretches before and after it, one reading high and the other
low, by as much as the whole step near the stop (long-haul `typical` seed 2 of the accuracy
matrix: −14 mm/s² during the 10-minute trailer change; the mass of the segment after it read
+4.4 % with σ 1.6 % after a weighing, `no-baro`; docs/estimation.md, "The accelerometer's bias
step at a standstill").

`standstill_steps` measures each step; `step_offsets` gives, per sample, the bias's change the
steps measured and the clock without those stretches of standing, so that the smoother is given the
accelerometer with the steps taken out (a bias that is continuous across standstills) and the
steps are put back into the bias it states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics import standing
from ..runs import true_runs


@dataclass(frozen=True)
class StepSettings:
    """Which standstills measure a bias step, over which parts of them, and when a step is one."""

    stop_speed_mps: float = 0.5
    """Speed below which the truck stands (`mass.segments.SegmentSettings.stop_speed_mps`)."""
    min_standstill_s: float = 60.0
    """Shortest standstill measured: the stops that bound mass segments
    (`mass.segments.SegmentSettings.min_stop_s`), long enough for two windows well apart."""
    settle_s: float = 5.0
    """Left out at either end of the standstill: the truck pitches on its springs as it stops and
    as it pulls away."""
    window_s: float = 20.0
    """Length of the two windows whose mean readings are compared [s]."""
    block_s: float = 1.0
    """Block length for the windows' noise [s]: the mean reading's σ from the scatter of block
    means, so that vibration correlated over a fraction of a second is not taken as averaging out."""
    false_alarm: float = 0.01
    """Probability of taking a step out where the bias did not step (shared over the drive's
    measured standstills, two-sided), as `mass.segments.SegmentSettings.payload_false_alarm` for a
    payload change: a step within its noise is left to the smoother."""


@dataclass(frozen=True)
class Step:
    """One standstill: its first sample and the one after its last (indices), the accelerometer's
    change over it [m/s²] and that change's 1-sigma [m/s²]."""

    start: int
    end: int
    step_mps2: float
    std_mps2: float


def _window_mean(values: np.ndarray, time_s: np.ndarray, pick: np.ndarray, block_s: float) -> tuple[float, float]:
    """Mean of ``values`` over the samples ``pick`` and its 1-sigma from the scatter of block
    means (NaN, NaN with fewer than three blocks)."""
    ok = pick & np.isfinite(values)
    if not ok.any():
        return np.nan, np.nan
    block = np.floor((time_s[ok] - time_s[ok][0]) / block_s).astype(int)
    sums, counts = np.bincount(block, weights=values[ok]), np.bincount(block)
    means = sums[counts > 0] / counts[counts > 0]
    if len(means) < 3:
        return np.nan, np.nan
    return float(np.mean(values[ok])), float(np.std(means, ddof=1) / np.sqrt(len(means)))


def standstill_steps(time_s, speed_mps, accel_x_mps2, settings: StepSettings = StepSettings()) -> list[Step]:
    """The bias steps beyond their noise: at every standstill of at least ``min_standstill_s``
    with driving before and after it, the accelerometer's mean over the last ``window_s`` less that
    over the first (``settle_s`` inside either end), kept where it passes the two-sided
    ``false_alarm`` quantile of its noise, shared over the measured standstills. A standstill whose
    windows have too few readings measures nothing."""
    from scipy.stats import norm
    time = np.asarray(time_s, dtype=float)
    accel = np.asarray(accel_x_mps2, dtype=float)
    stopped = standing(time, np.asarray(speed_mps, dtype=float), settings.stop_speed_mps)
    measured = []
    for start, end in true_runs(stopped):
        first_s, last_s = time[start], time[end - 1]
        if start == 0 or end == len(time) or last_s - first_s < settings.min_standstill_s:
            continue
        inside = np.zeros(len(time), bool)
        inside[start:end] = True
        early = inside & (time >= first_s + settings.settle_s) & (time < first_s + settings.settle_s + settings.window_s)
        late = inside & (time > last_s - settings.settle_s - settings.window_s) & (time <= last_s - settings.settle_s)
        (a_early, s_early), (a_late, s_late) = (_window_mean(accel, time, pick, settings.block_s)
                                                for pick in (early, late))
        if np.isfinite([a_early, a_late, s_early, s_late]).all():
            measured.append(Step(start, end, a_late - a_early, float(np.hypot(s_early, s_late))))
    limit = norm.ppf(1 - settings.false_alarm / (2 * max(len(measured), 1)))
    return [step for step in measured if abs(step.step_mps2) > limit * step.std_mps2]


def step_offsets(time_s, steps: list[Step], settings: StepSettings = StepSettings()
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample: the bias's change since the log's start that ``steps`` measured [m/s²] (a ramp
    between the centres of each standstill's two windows, where the readings were compared), its
    1-sigma [m/s²] (every step's noise, which the smoother splits between the stretches either side
    of its standstill as it split the whole step before), and the clock [s] with those stretches of
    standing taken out: the time over which the bias moves in ways no standstill measured (the
    smoother's bias rate, `kalman.BIAS_RATE`)."""
    time = np.asarray(time_s, dtype=float)
    offset = np.zeros(len(time))
    clock = time.copy()
    for step in steps:
        early = time[step.start] + settings.settle_s + settings.window_s / 2
        late = time[step.end - 1] - settings.settle_s - settings.window_s / 2
        offset += step.step_mps2 * np.clip((time - early) / max(late - early, 1e-9), 0.0, 1.0)
        clock -= np.clip(time - early, 0.0, late - early)
    std = np.full(len(time), float(np.sqrt(sum(step.std_mps2 ** 2 for step in steps))))
    return offset, std, clock
