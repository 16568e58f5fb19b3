"""How a walk ends at a stop: the chain conditioned on standing still at the cycle's last second.

A measured drive, and every VECTO mission cycle, ends with a deceleration to standstill. A walk
of ``n`` states is therefore drawn from the chain *conditioned on* its last state being a stop
(Doob's h-transform): over the last `WINDOW_S` seconds the transition to state ``j`` with
``r`` seconds left after it is drawn with weight ``count · h_r(j)``, where ``h_r(j)`` is the
chain's own probability of standing still ``r`` seconds after ``j``; before that window only
transitions from which a stop can still be reached in time are drawn (``steps_to_stop``), which
rarely excludes any. The walk thus slows down as the data slowed down before its stops, not by
the hardest braking the data holds, and every transition is still one of the counted ones. Only
in the window may a walk take a chain's ending transitions (`Chain.free_end`): into the censored
final stop of a one-way drive and the stretch that leads only there.

"A stop" is a standstill state the data stayed in for at least two seconds (a transition to
itself), so a walk that arrives early can stand until the end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .chain import Chain

WINDOW_S = 120
"""Seconds at the end of a walk drawn from the conditioned chain (a deceleration from 90 km/h at
0.5 m/s² takes 50 s; the conditioning needs room before it)."""
UNREACHABLE = np.int64(2**62)


@dataclass
class Ending:
    """What the kernels need to end walks at a stop.

    ``free_end[s]``: end of the transitions out of ``s`` drawn on a walk's way (`Chain.free_end`;
    those after it only in the last ``weight.shape[0]`` seconds); ``steps_to_stop[s]``: fewest transitions from state ``s`` to a stop (`UNREACHABLE` if none);
    ``reach_max[s]``: the largest of those over the states ``s`` leads to on its way (a draw from
    ``s`` with at least that many seconds left, before the window, is unconstrained);
    ``weight[r, j]``: ``h_r(j)``, the probability that the chain from ``j`` stands still ``r``
    seconds later, for ``r`` below the window (`WINDOW_S`; not longer, since conditioning a whole
    short walk on ending at a stop keeps it standing at its first stop; rows scaled by their
    largest value, only ratios within a row matter)."""

    free_end: np.ndarray
    steps_to_stop: np.ndarray
    reach_max: np.ndarray
    weight: np.ndarray

    @property
    def enabled(self) -> bool:
        return self.weight.shape[0] > 0

    def as_tuple(self) -> tuple:
        return self.free_end, self.steps_to_stop, self.reach_max, self.weight


def free_ending(chain: Chain) -> Ending:
    """No constraint: walks end wherever the chain takes them on its way (the generator before
    walks ended at a stop)."""
    zeros = np.zeros(chain.n_states, np.int64)
    return Ending(chain.free_end, zeros, zeros, np.zeros((0, chain.n_states)))


def stop_states(chain: Chain) -> np.ndarray:
    """Mask of the standstill states with a transition to themselves."""
    rows = np.repeat(np.arange(chain.n_states), np.diff(chain.row_ptr))
    mask = np.zeros(chain.n_states, bool)
    mask[rows[(rows == chain.dest) & (chain.speed_mps[rows] == 0)]] = True
    return mask


def _steps_to(target: np.ndarray, rows: np.ndarray, dest: np.ndarray) -> np.ndarray:
    """Fewest transitions to a ``target`` state from each state (breadth first, backwards)."""
    steps = np.where(target, 0, UNREACHABLE).astype(np.int64)
    level = 0
    while True:
        reached = steps[dest] == level
        fresh = np.unique(rows[reached])
        fresh = fresh[steps[fresh] == UNREACHABLE]
        if fresh.size == 0:
            return steps
        level += 1
        steps[fresh] = level


def _step_back(probability: np.ndarray, rows: np.ndarray, dest: np.ndarray, h: np.ndarray, n: int) -> np.ndarray:
    """The transition matrix (``probability`` of each transition ``rows`` → ``dest``) times ``h``:
    each row's products summed in their order from 0, as a CSR product sums them (bit for bit
    what scipy's gives), without importing scipy on the cycle's way (0.17 s of a first run)."""
    return np.bincount(rows, weights=probability * h[dest], minlength=n)


def ending_for(chain: Chain, n_steps: int, window_s: int = WINDOW_S) -> Ending:
    """The ending of walks of ``n_steps`` states through ``chain``; a free one when the chain has
    no stop (a drive that never stood for two seconds cannot end standing)."""
    target = stop_states(chain)
    if not target.any():
        return free_ending(chain)
    rows = np.repeat(np.arange(chain.n_states), np.diff(chain.row_ptr))
    steps = _steps_to(target, rows, chain.dest)
    drawn = chain.drawn
    reach_max = np.zeros(chain.n_states, np.int64)
    np.maximum.at(reach_max, rows[drawn], steps[chain.dest[drawn]])
    reach_max[chain.free_end == chain.row_ptr[:-1]] = UNREACHABLE
    total = np.add.reduceat(chain.count, chain.row_ptr[:-1]).astype(float)
    probability = chain.count / total[rows]
    window = int(max(min(window_s, n_steps - 1), 0))
    weight = np.empty((window, chain.n_states))
    if window:
        weight[0] = target
        for r in range(1, window):
            h = _step_back(probability, rows, chain.dest, weight[r - 1], chain.n_states)
            weight[r] = h / h.max()
    return Ending(chain.free_end, steps, reach_max, weight)
