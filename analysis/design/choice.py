"""Which feasible concept to recommend, and how sharply that choice is defined.

The default is the least cost of ownership: component cost plus the energy the concept draws from
the battery over its service life, at a stated price (T3CO's criterion). Unlike the Pareto front's
knee it does not depend on where the front happens to end: two fronts that agree near the optimum
give the same choice. The knee (`choose`, objectives normalised by the front's ends) and user
weights stay as options.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CHOICES = ("ownership", "knee")


@dataclass(frozen=True)
class Criterion:
    """A scalar score of candidates' objectives (battery kWh/km, component cost [EUR]); lower is better."""

    name: str
    """``ownership``, ``knee`` or ``weights``."""
    eur_per_kwh_per_km: float
    """Energy cost over the service life per kWh/km of consumption [EUR km/kWh]: price x lifetime distance."""
    weights: tuple[float, float] | None = None

    def ownership_eur(self, objectives: np.ndarray) -> np.ndarray:
        """Cost of ownership [EUR]: component cost plus lifetime energy cost."""
        objectives = np.atleast_2d(objectives)
        return objectives[:, 1] + self.eur_per_kwh_per_km * objectives[:, 0]


def criterion(options, daily_distance_m: float) -> Criterion:
    """The options' criterion; the lifetime distance is the day's distance x operating days x years."""
    lifetime_km = daily_distance_m / 1000.0 * options.operating_days_per_year * options.service_life_years
    name = "weights" if options.weights is not None else options.choice
    return Criterion(name, options.energy_price_eur_per_kwh * lifetime_km,
                     tuple(options.weights) if options.weights is not None else None)


def choose(front: np.ndarray, weights=None) -> int:
    """The front's knee: the point farthest from the line through its two ends (objectives
    normalised to [0, 1]); with weights, the least weighted sum of the normalised objectives."""
    low, high = front.min(axis=0), front.max(axis=0)
    f = (front - low) / np.where(high > low, high - low, 1.0)
    if weights is not None:
        return int(np.argmin(f @ np.asarray(weights, float)))
    if len(f) < 3:
        return int(np.argmin(f.sum(axis=1)))
    a, b = f[0], f[-1]
    direction = (b - a) / np.linalg.norm(b - a)
    offset = f - a
    distance = np.abs(offset[:, 0] * direction[1] - offset[:, 1] * direction[0])
    return int(np.argmax(distance))


def choose_by(rule: Criterion, front: np.ndarray) -> int:
    """Index into ``front`` (objectives of the Pareto front, cheapest first) of the concept ``rule`` picks."""
    if rule.name == "ownership":
        return int(np.argmin(rule.ownership_eur(front)))
    return choose(front, rule.weights)


def near_optimal(rule: Criterion, objectives: np.ndarray, feasible: np.ndarray, chosen: int,
                 share: float) -> np.ndarray:
    """Indices of the feasible candidates whose cost of ownership is at most ``share`` above the
    chosen concept's: the concepts the criterion cannot tell apart within that tolerance."""
    ownership = rule.ownership_eur(objectives)
    return np.flatnonzero(feasible & (ownership <= ownership[chosen] * (1.0 + share)))
