"""Criteria and score of a candidate against the measured data (physics.md; paper eq. (15)).

Relative deviation per criterion: d = |x_candidate − x_measured| / max(|x_measured|, σ_measured,
w). **[choice]** The paper divides by |x_measured|, which is ill-defined where a measured value is
near zero: the mean gradient of a round trip, the mean acceleration of any drive, a minimum
gradient of −0.2 %. The denominator is therefore at least the quantity's own measured standard
deviation σ (its scale, as in a standardised mean difference) and at least one class width w of
the quantity (speed class [m/s], gradient class [%], speed class per second for acceleration
[m/s²], mass class [kg]): a chain at that resolution cannot tell smaller differences apart.
Where |x_measured| is the larger (mean speed, mass, extremes), this is the paper's relative
deviation. The measured side is the data at class resolution (`TransitionCounts.statistics`), so
acceleration is compared like for like: both are 1 Hz differences of class-centre speeds
(docs/cycles.md says why that matters).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .classes import ClassWidths
from .counting import QUANTITIES, TransitionCounts, count_transitions

STATISTICS = ("mean", "std", "min", "max")
# (quantity index, statistic index, allowance), in the order of the paper's list.
CRITERIA = (
    (0, 0, 0.10), (0, 1, 0.10), (0, 3, 0.10),
    (1, 0, 0.15), (1, 1, 0.15), (1, 2, 0.15), (1, 3, 0.15),
    (2, 0, 0.15), (2, 1, 0.15), (2, 2, 0.15), (2, 3, 0.15),
    (3, 0, 0.15), (3, 1, 0.15), (3, 2, 0.15), (3, 3, 0.15),
)
NAMES = tuple(f"{QUANTITIES[q]}_{STATISTICS[s]}" for q, s, _ in CRITERIA)
ALLOWANCE = np.array([a for _, _, a in CRITERIA])
IS_MASS = np.array([q == 3 for q, _, _ in CRITERIA])
_Q = np.array([q for q, _, _ in CRITERIA])
_S = np.array([s for _, s, _ in CRITERIA])


def scales(measured_stats: np.ndarray, widths: ClassWidths) -> np.ndarray:
    """Denominator of the relative deviation per criterion (module docstring)."""
    per_quantity = np.maximum(measured_stats[:, 1],
                              [widths.speed_mps, widths.gradient_pct, widths.speed_mps, widths.mass_kg])
    return np.maximum(np.abs(measured_stats[_Q, _S]), per_quantity[_Q])


def deviations(candidate_stats: np.ndarray, measured_stats: np.ndarray, widths: ClassWidths) -> np.ndarray:
    """Relative deviations (…, 15) of candidate statistics (…, 4, 4) from measured ones (4, 4)."""
    candidate = candidate_stats[..., _Q, _S]
    return np.abs(candidate - measured_stats[_Q, _S]) / scales(measured_stats, widths)


def scores(deviation: np.ndarray, with_mass: bool = True) -> np.ndarray:
    """Score S = (1/n) Σ d_i / d_max,i (eq. (15)) over all criteria or all but mass."""
    ratio = deviation / ALLOWANCE
    return ratio.mean(axis=-1) if with_mass else ratio[..., ~IS_MASS].mean(axis=-1)


@dataclass
class Criteria:
    """One candidate judged: per criterion its value, the measured value, deviation, allowance."""

    candidate: np.ndarray
    measured: np.ndarray
    deviation: np.ndarray

    @property
    def passed(self) -> np.ndarray:
        return self.deviation <= ALLOWANCE

    @property
    def valid(self) -> bool:
        return bool(self.passed.all())

    @property
    def valid_without_mass(self) -> bool:
        return bool(self.passed[~IS_MASS].all())

    @property
    def score(self) -> float:
        return float(scores(self.deviation))

    @property
    def score_without_mass(self) -> float:
        return float(scores(self.deviation, with_mass=False))

    @property
    def failed(self) -> list[str]:
        return [name for name, ok in zip(NAMES, self.passed) if not ok]

    def statement(self) -> str:
        if self.valid:
            return f"valid on all {len(NAMES)} criteria, score {self.score:.3f}"
        worst = ", ".join(f"{NAMES[i]} {self.deviation[i]:.1%} > {ALLOWANCE[i]:.0%}"
                          for i in np.flatnonzero(~self.passed))
        return f"NOT valid, score {self.score:.3f}: failed {worst}"

    def as_dict(self) -> dict:
        return {
            "score": self.score, "score_without_mass": self.score_without_mass, "valid": self.valid,
            "valid_without_mass": self.valid_without_mass, "failed": self.failed,
            "criteria": {name: {"candidate": float(c), "measured": float(m), "deviation": float(d),
                                "allowance": float(a), "passed": bool(d <= a)}
                         for name, c, m, d, a in zip(NAMES, self.candidate, self.measured, self.deviation,
                                                     ALLOWANCE)},
        }


def cycle_statistics(cycle: pd.DataFrame) -> np.ndarray:
    """(mean, std, min, max) per quantity of a 1 Hz cycle (acceleration from speed differences)."""
    speed = cycle["speed_mps"].to_numpy(float)
    series = [speed, cycle["gradient_pct"].to_numpy(float), np.diff(speed), cycle["mass_kg"].to_numpy(float)]
    return np.array([[x.mean(), x.std(), x.min(), x.max()] for x in series])


def evaluate(candidate, measured, widths: ClassWidths | None = None) -> Criteria:
    """Judge a candidate (1 Hz cycle DataFrame or statistics (4, 4)) against measured data
    (`TransitionCounts`, or a signals DataFrame counted at ``widths``)."""
    if not isinstance(measured, TransitionCounts):
        measured = count_transitions(measured, widths)
    stats = cycle_statistics(candidate) if isinstance(candidate, pd.DataFrame) else np.asarray(candidate)
    reference = measured.statistics
    return Criteria(stats[_Q, _S], reference[_Q, _S], deviations(stats, reference, measured.widths))
