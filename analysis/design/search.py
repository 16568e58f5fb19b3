"""The concept search: pymoo's NSGA-II over the unit-cube encoding of `evaluate.decode`, each
generation's population simulated as one batch; then the Pareto front of every feasible
candidate seen, the chosen concept (knee, or the user's weights) and why the rest failed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .evaluate import N_VARIABLES, Evaluation, Evaluator, constraint_names


@dataclass
class SearchOutcome:
    x: np.ndarray
    """Every candidate simulated, unit-cube variables (rows)."""
    objectives: np.ndarray
    constraints: np.ndarray
    feasible: np.ndarray
    pareto: np.ndarray
    """Indices of the feasible non-dominated candidates, cheapest first."""
    chosen: int | None
    """Index of the chosen concept (None: nothing feasible)."""
    constraint_names: list[str]
    evaluations: list[Evaluation]


def run_search(evaluator: Evaluator, seed: int | None = None) -> SearchOutcome:
    """NSGA-II (Deb et al. 2002, pymoo 0.6) with ``population`` x ``generations`` candidates."""
    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.core.problem import Problem
    from pymoo.optimize import minimize

    options = evaluator.options
    names = constraint_names(options)
    evaluations: list[Evaluation] = []
    xs: list[np.ndarray] = []

    class ConceptProblem(Problem):
        def __init__(self):
            super().__init__(n_var=N_VARIABLES, n_obj=2, n_ieq_constr=len(names), xl=0.0, xu=1.0)

        def _evaluate(self, x, out, *args, **kwargs):
            e = evaluator.evaluate(x)
            evaluations.append(e)
            xs.append(np.array(x, float))
            out["F"], out["G"] = e.objectives, e.constraints

    minimize(ConceptProblem(), NSGA2(pop_size=int(options.population)), ("n_gen", int(options.generations)),
             seed=options.seed if seed is None else seed, verbose=False)
    if options.weights is not None:
        first = outcome(np.concatenate(xs), np.concatenate([e.objectives for e in evaluations]),
                        np.concatenate([e.constraints for e in evaluations]), names, evaluations, options.weights)
        if first.chosen is not None:
            polish(evaluator, first, options.weights, evaluations, xs, seed=options.seed)
    x = np.concatenate(xs)
    objectives = np.concatenate([e.objectives for e in evaluations])
    constraints = np.concatenate([e.constraints for e in evaluations])
    return outcome(x, objectives, constraints, names, evaluations, options.weights)


def outcome(x, objectives, constraints, names, evaluations, weights) -> SearchOutcome:
    feasible = np.all(constraints <= 0.0, axis=1)
    pareto = pareto_front(objectives, feasible)
    chosen = choose(objectives[pareto], weights) if len(pareto) else None
    return SearchOutcome(x, objectives, constraints, feasible, pareto,
                         int(pareto[chosen]) if chosen is not None else None, names, evaluations)


SLACK_WEIGHT = 1e-6
"""Weight of the constraints' summed slack against the normalised objectives in `polish`."""
CONTINUOUS = range(3, 9)
"""Decision variables polished locally (machine power and speed, ratios, inverter current,
battery); topology, machines and gears stay."""


def _directions(rng: np.random.Generator, n_random: int = 24) -> np.ndarray:
    """+-1 along each continuous variable, and ``n_random`` random unit directions among them
    (coupled variables, such as machine power, ratio, inverter current and battery along an
    active constraint, must move together)."""
    rows = []
    for a in CONTINUOUS:
        for sign in (1.0, -1.0):
            row = np.zeros(N_VARIABLES)
            row[a] = sign
            rows.append(row)
    random = np.zeros((n_random, N_VARIABLES))
    random[:, list(CONTINUOUS)] = rng.normal(size=(n_random, len(CONTINUOUS)))
    random /= np.linalg.norm(random, axis=1, keepdims=True)
    return np.vstack([rows, 2.0 * random])


def polish(evaluator: Evaluator, first: SearchOutcome, weights, evaluations: list, xs: list,
           step: float = 0.05, iterations: int = 40, seed: int = 0) -> None:
    """Pattern search (Kolda, Lewis & Torczon 2003) from the weighted choice: each iteration
    simulates the neighbours a step along `_directions` as one batch and moves to the
    best feasible one that lowers the weighted sum of the objectives (normalised by the front's
    spread; at equal sums, more slack in the constraints wins, so the search can slide along an
    active constraint), else halves the step. NSGA-II approaches a bound of the box only slowly; this finishes
    the user's choice. Every candidate tried joins the archive."""
    front = first.objectives[first.pareto]
    low, spread = front.min(axis=0), np.ptp(front, axis=0)
    scale = np.where(spread > 0, spread, np.abs(low) + 1e-9)
    w = np.asarray(weights, float)
    rng = np.random.default_rng(seed)
    x = first.x[first.chosen].copy()
    def scores(objectives, constraints):
        slack = np.clip(-constraints, 0.0, 1.0).sum(axis=1)
        return ((objectives - low) / scale) @ w - SLACK_WEIGHT * slack

    best = float(scores(first.objectives[[first.chosen]], first.constraints[[first.chosen]])[0])
    for _ in range(iterations):
        trial = np.clip(x[None, :] + step * _directions(rng), 0.0, 1.0)
        e = evaluator.evaluate(trial)
        evaluations.append(e)
        xs.append(trial)
        score = scores(e.objectives, e.constraints)
        score[~np.all(e.constraints <= 0.0, axis=1)] = np.inf
        k = int(np.argmin(score))
        if score[k] < best - 1e-12:
            x, best = trial[k], float(score[k])
        else:
            step *= 0.5
            if step < 1e-3:
                break


def pareto_front(objectives: np.ndarray, feasible: np.ndarray) -> np.ndarray:
    """Indices of the feasible candidates no other feasible candidate dominates, by the second objective."""
    index = np.flatnonzero(feasible)
    f = objectives[index]
    keep = []
    for k in range(len(index)):
        dominated = np.any(np.all(f <= f[k], axis=1) & np.any(f < f[k], axis=1))
        if not dominated:
            keep.append(k)
    front = index[keep]
    _, unique = np.unique(objectives[front].round(9), axis=0, return_index=True)
    front = front[unique]
    return front[np.argsort(objectives[front, 1], kind="stable")]


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


def exclusions(out: SearchOutcome, regions: list[str]) -> dict:
    """Why candidates failed: per constraint how many broke it and for how many it was the only
    one broken; per region (topology, machines, gears) the constraint broken most. With nothing
    feasible, the binding constraint is the first (static ones first) that every candidate broke,
    else the one the least infeasible candidate broke most."""
    violated = out.constraints > 0.0
    only = violated & (violated.sum(axis=1, keepdims=True) == 1)
    by_constraint = {name: {"violated": int(violated[:, k].sum()), "only_violation": int(only[:, k].sum())}
                     for k, name in enumerate(out.constraint_names)}
    by_region = {}
    regions = np.asarray(regions)
    for region in sorted(set(regions)):
        rows = regions == region
        bad = violated[rows & ~out.feasible]
        entry = {"candidates": int(rows.sum()), "feasible": int((rows & out.feasible).sum())}
        if len(bad):
            counts = bad.sum(axis=0)
            entry["most_violated"] = out.constraint_names[int(np.argmax(counts))]
            entry["most_violated_share"] = float(counts.max() / len(bad))
        by_region[region] = entry
    binding, by_all = None, [name for k, name in enumerate(out.constraint_names) if violated[:, k].all()]
    if not out.feasible.any():
        closest = int(np.argmin(np.clip(out.constraints, 0.0, None).sum(axis=1)))
        binding = by_all[0] if by_all else out.constraint_names[int(np.argmax(out.constraints[closest]))]
    return {"by_constraint": by_constraint, "by_region": by_region, "binding_constraint": binding,
            "broken_by_every_candidate": by_all}
