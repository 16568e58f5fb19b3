"""The concept search: pymoo's NSGA-II over the unit-cube encoding of `evaluate.decode`, each
generation's population simulated as one batch; a pattern search finishing the criterion's best
concepts; then the Pareto front of every feasible candidate seen, the chosen concept (`choice`)
and why the rest failed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .choice import Criterion, choose_by
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


POLISH_STARTS = 3
"""Regions (topology, machines, gears) whose best concept the pattern search finishes: regions'
optima lie close (on the demo one and two machines 2 % apart in cost of ownership), closer than
NSGA-II leaves a region's best from its optimum."""
POLISH_BUDGET = 1.0
"""The pattern search simulates at most this many candidates per NSGA-II candidate, over all starts."""


def run_search(evaluator: Evaluator, rule: Criterion, seed: int | None = None) -> SearchOutcome:
    """NSGA-II (Deb et al. 2002, pymoo 0.6) with ``population`` x ``generations`` candidates, then
    `polish` from the best concept of each of the `POLISH_STARTS` best regions by ``rule`` (the
    knee is a point of the front, not a score: it is not polished)."""
    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.core.problem import Problem
    from pymoo.optimize import minimize

    options = evaluator.options
    seed = options.seed if seed is None else seed
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
             seed=seed, verbose=False)

    def archive() -> SearchOutcome:
        return outcome(np.concatenate(xs), np.concatenate([e.objectives for e in evaluations]),
                       np.concatenate([e.constraints for e in evaluations]), names, evaluations, rule)

    first = archive()
    if rule.name != "knee" and first.chosen is not None:
        score = _score(rule, first)
        values = score(first.objectives, first.constraints)
        budget = evaluator.evaluated + POLISH_BUDGET * len(first.x)
        for k, start in enumerate(polish_starts(evaluator, first, values)):
            polish(evaluator, first.x[start], float(values[start]), score, evaluations, xs, seed=seed + k,
                   budget=budget)
        return archive()
    return first


def _score(rule: Criterion, first: SearchOutcome):
    """The polished score of (objectives, constraints): the criterion, scaled to about 1, less
    `SLACK_WEIGHT` x the constraints' slack (at equal scores, slack wins, so the search can slide
    along an active constraint)."""
    if rule.name == "ownership":
        scale = float(rule.ownership_eur(first.objectives[first.chosen])[0])

        def criterion(objectives):
            return rule.ownership_eur(objectives) / scale
    else:
        front = first.objectives[first.pareto]
        low, spread = front.min(axis=0), np.ptp(front, axis=0)
        norm = np.where(spread > 0, spread, np.abs(low) + 1e-9)
        w = np.asarray(rule.weights, float)

        def criterion(objectives):
            return ((objectives - low) / norm) @ w

    def score(objectives, constraints):
        slack = np.clip(-constraints, 0.0, 1.0).sum(axis=1)
        value = criterion(objectives) - SLACK_WEIGHT * slack
        return np.where(np.all(constraints <= 0.0, axis=1), value, np.inf)

    return score


def polish_starts(evaluator: Evaluator, first: SearchOutcome, values: np.ndarray) -> list[int]:
    """The best feasible candidate (by ``values``, the score of each) of each of the
    `POLISH_STARTS` regions (topology, machines, gears) with the best scores, best first."""
    c = evaluator.decode(first.x)
    best: dict[tuple, int] = {}
    for i in np.flatnonzero(np.isfinite(values)):
        region = (int(c.topology[i]), int(c.machines[i]), int(c.speeds[i]))
        if region not in best or values[i] < values[best[region]]:
            best[region] = int(i)
    return sorted(best.values(), key=lambda i: values[i])[:POLISH_STARTS]


def outcome(x, objectives, constraints, names, evaluations, rule: Criterion) -> SearchOutcome:
    feasible = np.all(constraints <= 0.0, axis=1)
    pareto = pareto_front(objectives, feasible)
    chosen = choose_by(rule, objectives[pareto]) if len(pareto) else None
    return SearchOutcome(x, objectives, constraints, feasible, pareto,
                         int(pareto[chosen]) if chosen is not None else None, names, evaluations)


SLACK_WEIGHT = 1e-6
"""Weight of the constraints' summed slack against the normalised objectives in `polish`."""
CONTINUOUS = range(3, 9)
"""Decision variables polished locally (machine power and speed, ratios, inverter current,
battery); topology, machines and gears move by `region_neighbours`."""


def region_neighbours(x: np.ndarray, options) -> np.ndarray:
    """``x`` moved into every other region (topology, machines, gears) of the design space, the
    continuous variables kept and one machine's power scaled so the total stays: the discrete
    neighbours of a mixed-variable pattern search (Audet & Dennis 2001). NSGA-II's population
    settles in one region early, and which one depends on the seed."""
    from . import components as C
    from .evaluate import decode

    here = decode(x, options, 1.0, 1.0)  # voltage and wheel radius do not change the region
    allowed = [C.TOPOLOGIES.index(t) for t in options.topologies]
    p_lo, p_hi = options.machine_power_range_w
    rows = []
    for k, topology in enumerate(allowed):
        lo, hi = C.SPEEDS[C.TOPOLOGIES[topology]]
        for machines in range(1, options.max_machines + 1):
            for gears in range(lo, hi + 1):
                if (topology, machines, gears) == (here.topology[0], here.machines[0], here.speeds[0]):
                    continue
                row = x.copy()
                row[0] = (k + 0.5) / len(allowed)
                row[1] = (machines - 0.5) / options.max_machines
                row[2] = (gears - lo + 0.5) / (hi - lo + 1)
                if p_hi > p_lo:
                    row[3] = np.clip(x[3] + np.log(here.machines[0] / machines) / np.log(p_hi / p_lo), 0.0, 1.0)
                rows.append(row)
    return np.array(rows).reshape(-1, len(x))


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


def polish(evaluator: Evaluator, x: np.ndarray, best: float, score, evaluations: list, xs: list,
           step: float = 0.05, iterations: int = 40, seed: int = 0, budget: float = np.inf) -> None:
    """Mixed-variable pattern search (Kolda, Lewis & Torczon 2003; Audet & Dennis 2001) from ``x``
    (of score ``best``): each iteration simulates the neighbours a step along `_directions` and
    the point in the other regions (`region_neighbours`) as one batch and moves to the one that
    lowers ``score`` (of objectives and constraints; infinite where infeasible), else halves the step. NSGA-II
    approaches a bound of the box, and the optimum along an active constraint, only slowly; this
    finishes it. It stops once the evaluator has simulated ``budget`` candidates in all. Every
    candidate tried joins the archive."""
    rng = np.random.default_rng(seed)
    x = np.asarray(x, float).copy()
    moved = True
    for _ in range(iterations):
        if evaluator.evaluated >= budget:
            break
        trial = np.clip(x[None, :] + step * _directions(rng), 0.0, 1.0)
        if moved:  # the other regions at this point; tried again only once the point has moved
            trial = np.vstack([trial, region_neighbours(x, evaluator.options)])
        e = evaluator.evaluate(trial)
        evaluations.append(e)
        xs.append(trial)
        values = score(e.objectives, e.constraints)
        k = int(np.argmin(values))
        moved = bool(values[k] < best - 1e-12)
        if moved:
            x, best = trial[k], float(values[k])
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
