"""Monte Carlo selection: many candidates scored in batches, the best valid one drawn again."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .chain import Chain, build_chain
from .counting import TransitionCounts
from .criteria import ALLOWANCE, IS_MASS, Criteria, deviations, evaluate, scores
from .generate import cycle_frame, run_batch, walk_ending

BATCH = 2000


@dataclass
class Selection:
    """The chosen cycle, how it was judged, and how the whole candidate set did."""

    cycle: pd.DataFrame
    criteria: Criteria
    index: int
    seed: int
    n_candidates: int
    n_valid: int
    n_valid_without_mass: int
    all_scores: np.ndarray
    chain: Chain
    method: str = "paper"
    objective: float | None = None
    start_score: float | None = None
    load_criteria: dict | None = None
    trace: np.ndarray | None = field(default=None, repr=False)
    refined_scores: np.ndarray | None = field(default=None, repr=False)

    @property
    def loads_within_allowance(self) -> bool | None:
        if self.load_criteria is None:
            return None
        from .load_criteria import within_allowance
        return within_allowance(self.load_criteria)

    def as_dict(self) -> dict:
        extra = {}
        if self.method != "paper":
            extra = {"objective": self.objective, "start_score": self.start_score,
                     "refined_scores": [float(x) for x in self.refined_scores]
                     if self.refined_scores is not None else None,
                     "moves": int(len(self.trace)) if self.trace is not None else 0}
        if self.load_criteria is not None:
            extra["load_criteria"] = self.load_criteria
            extra["loads_within_allowance"] = self.loads_within_allowance
        return {**self.criteria.as_dict(), "statement": self.criteria.statement(), "method": self.method,
                **extra, "candidate_index": self.index,
                "seed": self.seed, "n_candidates": self.n_candidates, "n_valid": self.n_valid,
                "n_valid_without_mass": self.n_valid_without_mass,
                "score_median": float(np.median(self.all_scores)), "states": self.chain.n_states,
                "states_observed": self.chain.n_states_observed,
                "transitions": int(len(self.chain.count)),
                "transitions_outside_kept_chain": self.chain.transitions_left_out}


def select_cycle(counts: TransitionCounts, duration_s: float = 1800.0, n_candidates: int = 100_000,
                 seed: int = 0, update_counts: bool = False, chain: Chain | None = None, end_at_stop: bool = True,
                 progress=None) -> Selection:
    """Generate ``n_candidates`` cycles of ``duration_s`` [s], score them (eq. (15)) and return the
    valid one with the lowest score S, or, if none is valid, the lowest-scoring one (its criteria
    say which failed). Cycles end at a stop unless ``end_at_stop`` is off (`ending`);
    ``progress("candidates", done, total, lowest S)`` after each batch."""
    chain = chain or build_chain(counts)
    ending = walk_ending(chain, duration_s, end_at_stop)
    measured = counts.statistics
    all_scores = np.empty(n_candidates)
    valid = np.empty(n_candidates, bool)
    valid_without_mass = np.empty(n_candidates, bool)
    for first in range(0, n_candidates, BATCH):
        size = min(BATCH, n_candidates - first)
        stats, _ = run_batch(chain, duration_s, size, seed, first, update_counts, ending=ending)
        deviation = deviations(stats, measured, counts.widths)
        all_scores[first:first + size] = scores(deviation)
        passed = deviation <= ALLOWANCE
        valid[first:first + size] = passed.all(axis=1)
        valid_without_mass[first:first + size] = passed[:, ~IS_MASS].all(axis=1)
        if progress:
            progress("candidates", first + size, n_candidates, float(all_scores[:first + size].min()))
    pool = np.flatnonzero(valid) if valid.any() else np.arange(n_candidates)
    best = int(pool[np.argmin(all_scores[pool])])
    _, path = run_batch(chain, duration_s, 1, seed, best, update_counts, keep_paths=True, ending=ending)
    cycle = cycle_frame(chain, path[0])
    return Selection(cycle, evaluate(cycle, counts), best, int(seed), n_candidates, int(valid.sum()),
                     int(valid_without_mass.sum()), all_scores, chain)
