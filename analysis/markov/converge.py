"""The default selection: a Monte Carlo pool, its best walks refined towards the criteria.

The paper's selection (`select.select_cycle`) keeps the best of a fixed budget of independent
walks; on one-way drives one walk in 10⁴–10⁵ is valid, so whether a user gets a cycle is luck.
Here the pool only provides starting points: the ``n_chains`` walks closest to validity (by the
kinematic part of the objective) are refined (`refine.refine_walk`) towards the fifteen criteria
and, when a vehicle and the measured drive's loads are given (`load_criteria.LoadTarget`), the
load criteria. The fifteen stay the validity gate; the objective adds the loads to the score.

The pool's batches and the walks of each refinement stage are independent (each its own seed
stream), so they run on threads side by side (the kernels release the GIL): the result is the one
a single thread gives, bit for bit, on every number of cores.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import precompile
from .chain import Chain, build_chain
from .counting import TransitionCounts
from .criteria import ALLOWANCE, IS_MASS, deviations, evaluate, scores
from .ending import Ending
from .generate import cycle_frame, run_batch, walk_ending
from .load_criteria import LOAD_ALLOWANCE, N_LOADS, LoadTarget, evaluate_loads
from .refine import kinematic_arrays, refine_walk
from .score_kernels import KINEMATIC_PENALTY
from .select import BATCH, Selection

POOL = 20_000
CHAINS = 12
MOVES = 3_000
SURVIVORS = 2
SHORTLIST = 16
MAX_WINDOW_S = 300
TEMPERATURE = 0.1
"""Start temperature of the annealing, in objective units (a tenth of one allowance, averaged)."""


Progress = Callable[[str, int, int, float], None]
"""``progress(what, done, total, best)``: after each batch of pool walks (``what`` "pool", ``best``
the lowest score S so far) and each refined walk ("refined", the lowest objective so far)."""


def _side_by_side(function, items: list, each: Callable | None = None) -> list:
    """``[function(item) for item in items]``, on as many threads as there are usable cores;
    ``each(i, result)`` in the calling thread as the results come, in order."""
    workers = min(len(items), len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
    results = []
    if workers <= 1:
        for item in items:
            results.append(function(item))
            if each:
                each(len(results) - 1, results[-1])
        return results
    with ThreadPoolExecutor(workers, thread_name_prefix="cycle-walks") as pool:
        for result in pool.map(function, items):
            results.append(result)
            if each:
                each(len(results) - 1, result)
    return results


def kinematic_objective(deviation: np.ndarray) -> np.ndarray:
    """The objective without loads of pool candidates (…, 15): `score_kernels.kinematic_objective`
    for many candidates at once."""
    ratio = deviation / ALLOWANCE
    return ratio.mean(axis=-1) + KINEMATIC_PENALTY * np.clip(ratio - 1.0, 0.0, None).sum(axis=-1)


def _pool(chain, counts, duration_s, n_pool, seed, update_counts, ending, progress, drawn=None):
    """Scores, kinematic objectives and validity of the ``n_pool`` candidates of ``seed``; ``drawn``
    the statistics of the first of them if another process drew them (`precompile.wait`)."""
    measured = counts.statistics
    all_scores, objective = np.empty(n_pool), np.empty(n_pool)
    valid, valid_without_mass = np.empty(n_pool, bool), np.empty(n_pool, bool)
    n_drawn = 0 if drawn is None else len(drawn)
    firsts = list(range(n_drawn, n_pool, BATCH))

    def score(first, stats):
        size = len(stats)
        deviation = deviations(stats, measured, counts.widths)
        all_scores[first:first + size] = scores(deviation)
        objective[first:first + size] = kinematic_objective(deviation)
        passed = deviation <= ALLOWANCE
        valid[first:first + size] = passed.all(axis=1)
        valid_without_mass[first:first + size] = passed[:, ~IS_MASS].all(axis=1)
        if progress:
            progress("pool", first + size, n_pool, float(all_scores[:first + size].min()))

    for first in range(0, n_drawn, BATCH):
        score(first, drawn[first:first + BATCH])
    _side_by_side(lambda first: run_batch(chain, duration_s, min(BATCH, n_pool - first), seed, first, update_counts,
                                          ending=ending)[0], firsts, lambda i, stats: score(firsts[i], stats))
    return all_scores, objective, valid, valid_without_mass


def _load_arrays(chain: Chain, target: LoadTarget | None):
    if target is None:
        edges = np.array([0.0, 1.0])
        return (np.zeros(chain.n_states), 1.0, edges, edges, np.zeros((1, 1)), 1.0, np.zeros(N_LOADS),
                np.ones(N_LOADS))
    return (target.resistance_n, target.wheel_radius_m, target.speed_edges_rpm, target.torque_edges_nm,
            target.residence_share, target.range_scale_nm, target.measured, target.scale)


def refine(chain: Chain, counts: TransitionCounts, path: np.ndarray, target: LoadTarget | None, n_moves: int,
           seed: int, stream: int, max_window_s: int = MAX_WINDOW_S,
           temperature: float = TEMPERATURE, ending: Ending | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """A refined copy of ``path``, the best objective after each move, and the objective of the
    best walk (of ``path`` itself when ``n_moves`` is 0); it ends as ``ending`` says (None: at a
    stop, `generate.walk_ending`)."""
    path = np.array(path, dtype=np.int64)
    ending = ending if ending is not None else walk_ending(chain, len(path) - 1)
    trace = np.empty(n_moves)
    resistance, radius, speed_edges, torque_edges, share, range_scale, load_measured, load_scale = \
        _load_arrays(chain, target)
    window = int(max(2, min(max_window_s, len(path) - 1)))
    best = refine_walk(path, chain.row_ptr, chain.dest, chain.count, chain.cum_count, chain.start_state,
                       chain.start_cum, ending.as_tuple(), *kinematic_arrays(chain, counts), target is not None, resistance,
                       radius, speed_edges, torque_edges, share, range_scale, load_measured, load_scale,
                       LOAD_ALLOWANCE, int(n_moves), window, float(temperature), int(seed), int(stream), trace)
    return path, trace, float(best)


def _starts(chain, counts, duration_s, seed, update_counts, objective, target, n_chains, ending) -> np.ndarray:
    """Pool indices to refine: the ``n_chains`` best by the whole objective among the
    `SHORTLIST` × ``n_chains`` best by its kinematic part (the pool keeps no paths and no loads)."""
    order = np.argsort(objective, kind="stable")
    if target is None:
        return order[:n_chains]
    shortlist = order[:SHORTLIST * n_chains]
    whole = np.array(_side_by_side(lambda i: refine(chain, counts, run_batch(chain, duration_s, 1, seed, int(i),
                                                                          update_counts, keep_paths=True,
                                                                          ending=ending)[1][0],
                                                    target, 0, seed, 0, ending=ending)[2], list(shortlist)))
    return shortlist[np.argsort(whole, kind="stable")[:n_chains]]


def select_refined(counts: TransitionCounts, duration_s: float = 1800.0, seed: int = 0, chain: Chain | None = None,
                   target: LoadTarget | None = None, vehicle=None, n_cycles: int = 1, n_pool: int = POOL,
                   n_chains: int | None = None, n_moves: int = MOVES, update_counts: bool = False,
                   max_window_s: int = MAX_WINDOW_S, temperature: float = TEMPERATURE,
                   survivors: int | None = SURVIVORS, end_at_stop: bool = True,
                   progress: Progress | None = None) -> list[Selection]:
    """``n_cycles`` cycles of ``duration_s`` [s], best first: the ``n_chains`` pool walks closest to
    validity, each refined over a quarter of ``n_moves`` moves; then the best ``survivors`` (at
    least ``n_cycles``) share the rest of the budget (``n_chains`` × ``n_moves`` moves in all),
    annealed from a third of the temperature (successive halving: a broad start, the effort on
    the promising walks). ``survivors`` None refines every walk over ``n_moves``. ``target`` and
    ``vehicle`` add the load criteria to the objective and to each selection's report. Walks end at
    a stop unless ``end_at_stop`` is off (`ending`); ``progress`` is told how far the search is."""
    chain = chain or build_chain(counts)
    ending = walk_ending(chain, duration_s, end_at_stop)
    n_chains = max(n_chains or CHAINS, n_cycles)
    n_pool = max(int(n_pool), n_chains)
    compiling = precompile.start(chain, counts, ending, duration_s, update_counts, n_pool=n_pool, seed=seed)
    try:
        if compiling is not None:  # the refinement's kernel here while the pool's compiles beside
            refine(chain, counts, np.full(2, chain.start_state[0]), target, 0, seed, 0, ending=ending)
    finally:
        drawn = precompile.wait(compiling)
    all_scores, objective, valid, valid_without_mass = _pool(chain, counts, duration_s, n_pool, seed, update_counts,
                                                             ending, progress, drawn)
    starts = _starts(chain, counts, duration_s, seed, update_counts, objective, target, n_chains, ending)
    first_moves = n_moves if not survivors else n_moves // 4
    keep = max(int(survivors), n_cycles) if survivors else 0
    n_refined = len(starts) + keep
    lowest = [np.inf]

    def refined(offset):
        def each(i, walk):
            lowest[0] = min(lowest[0], walk[0])
            if progress:
                progress("refined", offset + i + 1, n_refined, float(lowest[0]))
        return each

    def first_stage(stream_index):
        stream, index = stream_index
        _, path = run_batch(chain, duration_s, 1, seed, int(index), update_counts, keep_paths=True, ending=ending)
        refined_path, trace, best = refine(chain, counts, path[0], target, first_moves, seed, stream, max_window_s,
                                           temperature, ending)
        return best, int(index), refined_path, trace

    walks = _side_by_side(first_stage, list(enumerate(starts)), refined(0))
    if survivors:
        walks.sort(key=lambda w: w[0])
        more = (len(walks) * (n_moves - first_moves)) // keep

        def second_stage(i):
            _, index, path, trace = walks[i]
            refined_path, more_trace, best = refine(chain, counts, path, target, more, seed, len(walks) + i,
                                                    max_window_s, temperature * 0.3, ending)
            return best, index, refined_path, np.concatenate([trace, more_trace])

        walks = _side_by_side(second_stage, list(range(keep)), refined(len(starts)))
    results = []
    for best, index, refined, trace in walks:
        cycle = cycle_frame(chain, refined)
        criteria = evaluate(cycle, counts)
        loads = evaluate_loads(cycle, vehicle, target) if target is not None and vehicle is not None else None
        results.append(Selection(cycle, criteria, index, int(seed), n_pool, int(valid.sum()),
                                 int(valid_without_mass.sum()), all_scores, chain, method="refined",
                                 objective=best, start_score=float(all_scores[index]), load_criteria=loads,
                                 trace=trace))
    results.sort(key=lambda s: (not s.criteria.valid, s.objective))
    refined_scores = np.array([s.criteria.score for s in results])
    for s in results:
        s.refined_scores = refined_scores
    return results[:n_cycles]
