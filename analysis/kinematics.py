"""Distance and acceleration from wheel speed, on the signals table's own time base.

``accel_mps2`` is the derivative of wheel speed after a zero-phase low-pass (a centred moving
average of ``window_s``, 1 s by default): wheel speed is quantised (1/256 km/h on J1939, 1 km/h on
OBD-II) and differentiating it raw gives noise of several m/s² at 10 Hz. ``distance_m`` is the
trapezoidal integral of speed; samples outside ``valid`` contribute nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .runs import true_runs
from .stage import Stage

STANDING_GAP_S = 5.0
"""Longest gap in the speed [s] between two standing samples that still counts as standstill:
starting and ending at rest, a truck moves at most a t²/4 in it, under 10 m at 1.5 m/s²; a
logger's dropout in a long stop must not cut the stop in two."""


def distance_m(time_s: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
    """Driven distance [m]: trapezoidal integral of speed, NaN speeds counted as 0; a time step that
    goes back (two logs of a fleet joined) adds nothing."""
    speed = np.nan_to_num(np.asarray(speed_mps, dtype=float))
    steps = 0.5 * (speed[1:] + speed[:-1]) * np.clip(np.diff(np.asarray(time_s, dtype=float)), 0.0, None)
    return np.concatenate([[0.0], np.cumsum(steps)])


def standing(time_s: np.ndarray, speed_mps: np.ndarray, stop_speed_mps: float,
             max_gap_s: float = STANDING_GAP_S) -> np.ndarray:
    """Samples at standstill: speed below ``stop_speed_mps``, and the missing speeds of a gap of at
    most ``max_gap_s`` between two standing samples. Any other missing speed is not a stop (a gap
    is no evidence of a load change)."""
    time = np.asarray(time_s, dtype=float)
    speed = np.asarray(speed_mps, dtype=float)
    stopped = speed < stop_speed_mps
    for a, b in true_runs(np.isnan(speed)):
        if 0 < a and b < len(speed) and stopped[a - 1] and stopped[b] and time[b] - time[a - 1] <= max_gap_s:
            stopped[a:b] = True
    return stopped


def sample_step_s(time_s, default_s: float = 0.1) -> float:
    """The table's sample period [s]: the median of its positive time steps (``default_s`` with none)."""
    steps = np.diff(np.asarray(time_s, dtype=float))
    return float(np.median(steps[steps > 0])) if np.any(steps > 0) else default_s


def acceleration_mps2(time_s: np.ndarray, speed_mps: np.ndarray, window_s: float = 1.0) -> np.ndarray:
    """Longitudinal acceleration [m/s²] from speed: centred moving average, then central difference."""
    time = np.asarray(time_s, dtype=float)
    speed = pd.Series(np.asarray(speed_mps, dtype=float))
    dt = np.nanmedian(np.diff(time)) if len(time) > 1 else 1.0
    window = max(1, int(round(window_s / dt)))
    smooth = speed.rolling(window, center=True, min_periods=1).mean().to_numpy()
    if len(time) < 2:
        return np.zeros_like(smooth)
    return np.gradient(smooth, time)


@dataclass(frozen=True)
class KinematicsOptions:
    """Options of the kinematics stage."""

    accel_window_s: float = 1.0
    """Length of the centred moving average before differentiating speed [s]."""


@dataclass
class KinematicsResult:
    """The drive's length and duration."""

    distance_km: float
    duration_s: float

    def summary(self) -> dict:
        return {"distance_km": self.distance_km, "duration_s": self.duration_s}


def kinematics_stage(ctx) -> KinematicsResult:
    """Add ``distance_m`` [m] and ``accel_mps2`` [m/s²] to ``ctx.signals`` where it has none (a
    log never has; a signals table may bring its own), NaN where a row is not ``valid``.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``signals`` (time_s [s], speed_mps [m/s], valid) and ``options.kinematics`` (`KinematicsOptions`).
    """
    frame = ctx.signals
    time_s, speed_mps = frame["time_s"].to_numpy(), frame["speed_mps"].to_numpy()
    if "distance_m" not in frame.columns:
        frame["distance_m"] = distance_m(time_s, speed_mps)
    if "accel_mps2" not in frame.columns:
        accel = acceleration_mps2(time_s, speed_mps, ctx.options.kinematics.accel_window_s)
        frame["accel_mps2"] = np.where(frame["valid"].to_numpy(bool), accel, np.nan) if "valid" in frame else accel
    return KinematicsResult(float(frame["distance_m"].iloc[-1] / 1000.0),
                            float(frame["time_s"].iloc[-1] - frame["time_s"].iloc[0]))


STAGE = Stage("kinematics", KinematicsOptions, kinematics_stage, summary_key="")
