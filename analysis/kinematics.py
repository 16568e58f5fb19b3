"""Distance and acceleration from wheel speed, on the signals table's own time base, at the GPS
track's scale where the track measures the wheel's.

``accel_mps2`` is the derivative of wheel speed after a zero-phase low-pass (a centred moving
average of ``window_s``, 1 s by default): wheel speed is quantised (1/256 km/h on J1939, 1 km/h on
OBD-II) and differentiating it raw gives noise of several m/s² at 10 Hz. ``distance_m`` is the
trapezoidal integral of speed; samples outside ``valid`` contribute nothing.

A wheel-speed signal reads (1 + ε) times the true speed (tyre wear, pressure, load, a tyre size the
controller does not know: 1-3 % is usual). Where the GPS track measures ε
(`distance_scale.wheel_distance_scale`) the stage divides ``speed_mps``, ``accel_mps2`` and
``distance_m`` by (1 + ε) once, for every stage after it (the road's grid, the mass, the cycle, the
loads, the energy per km), and keeps the wheel's own reading as ``wheel_speed_mps``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .distance_scale import wheel_distance_scale
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
    speed_over_track: bool = True
    """Take ``speed_mps``, ``accel_mps2`` and ``distance_m`` at the GPS track's scale where the track
    measures the wheel's (`distance_scale`); off: the wheel's own, with ε only stated."""


@dataclass
class KinematicsResult:
    """The drive's length and duration, and the wheel's scale against the GPS track."""

    distance_km: float
    duration_s: float
    wheel_speed_scale: float | None = None
    """ε [-]: the wheel's speed over the GPS track's, less 1 (None: the track tells none)."""
    corrected: bool = False
    """Whether speed, acceleration and distance were divided by (1 + ε)."""
    wheel_distance_km: float | None = None
    """The wheel's own distance [km]."""
    notes: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        return {"distance_km": self.distance_km, "duration_s": self.duration_s,
                "odometer": {"scale_pct": None if self.wheel_speed_scale is None else 100 * self.wheel_speed_scale,
                             "corrected": self.corrected, "wheel_distance_km": self.wheel_distance_km,
                             "notes": list(self.notes)}}


def add_kinematics(frame: pd.DataFrame, options: KinematicsOptions = KinematicsOptions()) -> KinematicsResult:
    """Add ``distance_m`` [m] and ``accel_mps2`` [m/s²] to ``frame`` (in place) where it has none (a
    log never has; a signals table may bring its own), NaN where a row is not ``valid``; where the
    GPS track measures the wheel's scale ε, divide them and ``speed_mps`` by (1 + ε) and keep the
    wheel's speed as ``wheel_speed_mps``.

    A table that already holds ``wheel_speed_mps`` (one this stage wrote) starts again from it: its
    ``speed_mps`` set back to the wheel's, its ``distance_m`` and ``accel_mps2`` made anew, so ε is
    applied once, measured from what the table holds now (a logger without GPS gets the wheel's)."""
    if "wheel_speed_mps" in frame.columns:
        frame["speed_mps"] = frame["wheel_speed_mps"]
        for name in ("wheel_speed_mps", "distance_m", "accel_mps2"):
            if name in frame.columns:
                del frame[name]
    time_s, speed_mps = frame["time_s"].to_numpy(), frame["speed_mps"].to_numpy()
    if "distance_m" not in frame.columns:
        frame["distance_m"] = distance_m(time_s, speed_mps)
    if "accel_mps2" not in frame.columns:
        accel = acceleration_mps2(time_s, speed_mps, options.accel_window_s)
        frame["accel_mps2"] = np.where(frame["valid"].to_numpy(bool), accel, np.nan) if "valid" in frame else accel
    wheel_km = float(frame["distance_m"].iloc[-1] / 1000.0)
    scale = wheel_distance_scale(frame)
    notes = []
    if scale is None:
        notes.append("speed and distance are the wheel's: "
                     + ("the GPS track tells no scale of the wheel's (too little open-sky track, or none "
                        "told from 0)" if "latitude_deg" in frame.columns and frame["latitude_deg"].notna().any()
                        else "the log has no GPS track to measure the wheel's scale against"))
    elif options.speed_over_track:
        frame["wheel_speed_mps"] = frame["speed_mps"]
        for name in ("speed_mps", "accel_mps2", "distance_m"):
            frame[name] = frame[name] / (1 + scale)
        notes.append(f"the wheel's speed reads {100 * scale:+.2f} % against the GPS track: speed, acceleration "
                     f"and distance divided by {1 + scale:.4f} for every stage ({wheel_km:.2f} km on the wheel, "
                     f"{wheel_km / (1 + scale):.2f} km on the track's scale); the wheel's own reading is "
                     f"wheel_speed_mps")
    else:
        notes.append(f"the wheel's speed reads {100 * scale:+.2f} % against the GPS track: not corrected "
                     f"(kinematics option speed_over_track off)")
    return KinematicsResult(float(frame["distance_m"].iloc[-1] / 1000.0),
                            float(frame["time_s"].iloc[-1] - frame["time_s"].iloc[0]), scale,
                            scale is not None and options.speed_over_track, wheel_km, notes)


def kinematics_stage(ctx) -> KinematicsResult:
    """Distance, acceleration and the speed at the GPS track's scale into ``ctx.signals``
    (`add_kinematics`), saying what it corrected.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``signals`` (time_s [s], speed_mps [m/s], valid; the GPS track) and
        ``options.kinematics`` (`KinematicsOptions`).
    """
    result = add_kinematics(ctx.signals, ctx.options.kinematics)
    for note in result.notes:
        ctx.say(f"kinematics: {note}")
    return result


STAGE = Stage("kinematics", KinematicsOptions, kinematics_stage, summary_key="")
