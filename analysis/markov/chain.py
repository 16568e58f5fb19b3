"""The chain ready to draw from: observed states, rows of outgoing transitions (CSR), start states.

Only the largest strongly connected part of the transition graph that contains a standstill is
kept, so a walk can never run into a state without a way out (the last sample of a log) or into a
closed trap (a state the data never left again). States outside it are reported, not drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import UserError
from . import classes as cls
from .counting import TransitionCounts


class ChainError(UserError):
    pass


@dataclass
class Chain:
    """CSR form of the counts over the kept states.

    ``row_ptr[s]:row_ptr[s+1]`` are the transitions out of state ``s`` to ``dest`` with ``count``
    and per-row cumulative counts ``cum_count``; ``start_state``/``start_cum`` the states a cycle
    starts in: **[choice]** the first second of a stop, weighted by how often the data arrived
    there, so a cycle opens with a whole stop of typical length (starting anywhere in a stop
    would favour long stops); without stops, any standstill (or any state) by its occupancy. Class centres per state in
    ``speed_mps`` [m/s], ``gradient_pct`` [%], ``mass_kg`` [kg].
    """

    widths: cls.ClassWidths
    keys: np.ndarray
    row_ptr: np.ndarray
    dest: np.ndarray
    count: np.ndarray
    cum_count: np.ndarray
    start_state: np.ndarray
    start_cum: np.ndarray
    speed_mps: np.ndarray
    gradient_pct: np.ndarray
    mass_kg: np.ndarray
    n_states_observed: int
    transitions_left_out: int

    @property
    def n_states(self) -> int:
        return len(self.keys)

    def probabilities(self) -> np.ndarray:
        """Transition probability of each stored transition (its row normalised)."""
        totals = np.add.reduceat(self.count, self.row_ptr[:-1])
        return self.count / np.repeat(totals, np.diff(self.row_ptr))


def build_chain(counts: TransitionCounts) -> Chain:
    """Keep the largest strongly connected part with a standstill; lay it out as CSR rows."""
    if len(counts) == 0:
        raise ChainError("no transitions counted: the data has fewer than two usable 1 Hz samples in a row")
    states = np.unique(np.concatenate([counts.from_key, counts.to_key]))
    src = np.searchsorted(states, counts.from_key)
    dst = np.searchsorted(states, counts.to_key)
    graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(len(states), len(states))).tocsr()
    _, label = connected_components(graph, directed=True, connection="strong")
    standstill = cls.decode(states)[0] == 0
    weight = np.bincount(label[src], weights=counts.count, minlength=label.max() + 1)
    eligible = np.unique(label[standstill]) if standstill.any() else np.arange(label.max() + 1)
    best = eligible[np.argmax(weight[eligible])]
    keep_state = label == best
    keep = keep_state[src] & keep_state[dst]
    if not keep.any():
        raise ChainError("the data never returns to any state it visited: too few samples for a chain "
                         "at these class widths (use wider classes or more data)")
    new_id = np.cumsum(keep_state) - 1
    s, d, c = new_id[src[keep]], new_id[dst[keep]], counts.count[keep]
    order = np.lexsort((d, s))
    s, d, c = s[order], d[order], c[order].astype(np.int64)
    n = int(keep_state.sum())
    row_ptr = np.concatenate([[0], np.cumsum(np.bincount(s, minlength=n))]).astype(np.int64)
    cum = np.cumsum(c)
    cum_count = cum - np.repeat(np.concatenate([[0], cum[row_ptr[1:-1] - 1]]), np.diff(row_ptr))
    keys = states[keep_state]
    speed, gradient, mass = cls.centres(keys, counts.widths)
    arrivals = np.bincount(d, weights=c * ((speed[s] > 0) & (speed[d] == 0)), minlength=n)
    if arrivals.any():
        start = np.flatnonzero(arrivals)
        weight = arrivals[start]
    else:
        occupancy = np.add.reduceat(c, row_ptr[:-1])
        start = np.flatnonzero(speed == 0) if np.any(speed == 0) else np.arange(n)
        weight = occupancy[start]
    return Chain(counts.widths, keys, row_ptr, d.astype(np.int64), c, cum_count.astype(np.int64),
                 start.astype(np.int64), np.cumsum(weight).astype(np.int64),
                 speed, gradient, mass, len(states), int(counts.count[~keep].sum()))
