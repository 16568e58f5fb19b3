"""The chain ready to draw from: observed states, rows of outgoing transitions (CSR), start states.

Two kinds of states carry no information about how driving goes on, and are pruned with the
transitions into them, repeatedly, until none is left: a state the data never left (the last
sample of a log cut while driving), and a stop the data never left (the parking at the end of a
one-way drive; the log ends, so how long the truck stood there is censored, and keeping it would
make a stop that lasts for ever, which every walk that finds a shortcut to the route's end falls
into). What remains lets a walk go on for any duration.

The censored final stop and the way into it are kept apart, as *ending* transitions (last in their
rows, after ``free_end``): a walk never draws them on its way, only when it ends (`ending`), so a
cycle can end as a one-way drive ends, at its final stop, and the stretch before it (which leads
only there) is part of cycles that end with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
    there or began a drive there, so a cycle opens with a whole stop of typical length (starting
    anywhere in a stop would favour long stops); without stops, any state by its occupancy. Class centres per state in ``speed_mps`` [m/s], ``gradient_pct``
    [%], ``mass_kg`` [kg]. ``row_ptr[s]:free_end[s]`` are the transitions a walk draws on its way,
    ``free_end[s]:row_ptr[s+1]`` those only a walk's ending draws (into the censored final stop).
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
    free_end: np.ndarray | None = None

    def __post_init__(self):
        if self.free_end is None:
            self.free_end = self.row_ptr[1:].copy()

    @property
    def drawn(self) -> np.ndarray:
        """Mask of the transitions a walk draws on its way (not only when it ends)."""
        rows = np.repeat(np.arange(len(self.row_ptr) - 1), np.diff(self.row_ptr))
        return np.arange(len(self.dest)) < self.free_end[rows]

    @property
    def n_states(self) -> int:
        return len(self.keys)


def _strong_components(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Label of each of ``n`` nodes' strongly connected component in the graph of edges
    ``src`` → ``dst`` (Tarjan's algorithm, without recursion)."""
    order = np.argsort(src, kind="stable")
    target = dst[order].tolist()
    first = np.searchsorted(src[order], np.arange(n + 1)).tolist()
    index, low, label = [-1] * n, [0] * n, [-1] * n
    on_stack = [False] * n
    stack: list[int] = []
    visited = n_parts = 0
    for root in range(n):
        if index[root] >= 0:
            continue
        index[root] = low[root] = visited
        visited += 1
        stack.append(root)
        on_stack[root] = True
        work = [[root, first[root]]]
        while work:
            frame = work[-1]
            v, i = frame
            if i < first[v + 1]:
                frame[1] = i + 1
                w = target[i]
                if index[w] < 0:
                    index[w] = low[w] = visited
                    visited += 1
                    stack.append(w)
                    on_stack[w] = True
                    work.append([w, first[w]])
                elif on_stack[w]:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    label[w] = n_parts
                    if w == v:
                        break
                n_parts += 1
    return np.array(label, dtype=np.int64)


def _parking(src: np.ndarray, dst: np.ndarray, n: int, standstill: np.ndarray) -> np.ndarray:
    """States in a closed set of standstill states only (a stop the data never left): the strongly
    connected parts of the graph of standstill states alone that no transition leaves and some
    transition starts in. (A part of the whole graph with standstill states only is one of these,
    and one of these that no transition leaves is a part of the whole graph.) The standstill
    states are few: this is cheap without a graph library."""
    still_state = np.flatnonzero(standstill)
    compact = np.full(n, -1, np.int64)
    compact[still_state] = np.arange(len(still_state))
    both = standstill[src] & standstill[dst]
    still_label = _strong_components(len(still_state), compact[src[both]], compact[dst[both]])
    label = np.full(n, -1, np.int64)
    label[still_state] = still_label
    n_parts = int(still_label.max()) + 1 if len(still_label) else 0
    from_still = standstill[src]
    closed = np.ones(n_parts, bool)
    closed[label[src[from_still & (label[src] != label[dst])]]] = False
    used = np.zeros(n_parts, bool)
    used[label[src[from_still]]] = True
    parking = np.zeros(n, bool)
    parking[still_state] = (closed & used)[still_label]
    return parking


def _prune(src: np.ndarray, dst: np.ndarray, n: int, standstill: np.ndarray) -> np.ndarray:
    """Mask of transitions kept after removing, repeatedly, those into states without a way on
    (no transition out, or a stop never left)."""
    keep = np.ones(len(src), bool)
    while True:
        has_exit = np.bincount(src[keep], minlength=n) > 0
        stuck = ~has_exit
        if keep.any():
            stuck |= _parking(src[keep], dst[keep], n, standstill)
        drop = keep & stuck[dst]
        if not drop.any():
            return keep
        keep &= ~drop


def _ending_only(src: np.ndarray, dst: np.ndarray, keep: np.ndarray, standstill: np.ndarray) -> np.ndarray:
    """Mask of the pruned transitions on a way from a kept state into a pruned stop that lasted
    (a standstill state with a transition to itself: a censored final stop)."""
    n = len(standstill)
    kept_state = np.zeros(n, bool)
    kept_state[src[keep]] = True
    dropped = ~keep
    leads = np.zeros(n, bool)
    leads[src[dropped & (src == dst) & standstill[src]]] = True
    leads &= ~kept_state
    while True:
        more = dropped & leads[dst] & ~kept_state[src] & ~leads[src]
        if not more.any():
            break
        leads[src[more]] = True
    reached = kept_state.copy()
    while True:
        more = dropped & leads[dst] & reached[src] & ~reached[dst]
        if not more.any():
            return dropped & leads[dst] & reached[src]
        reached[dst[more]] = True


def build_chain(counts: TransitionCounts) -> Chain:
    """Prune dead ends, keep the ways into a censored final stop as endings, choose start states,
    lay the rows out as CSR."""
    if len(counts) == 0:
        raise ChainError("no transitions counted: the data has fewer than two usable 1 Hz samples in a row")
    states = np.unique(np.concatenate([counts.from_key, counts.to_key]))
    src_all = np.searchsorted(states, counts.from_key)
    dst_all = np.searchsorted(states, counts.to_key)
    standstill_all = cls.decode(states)[0] == 0
    keep = _prune(src_all, dst_all, len(states), standstill_all)
    if not keep.any():
        raise ChainError("the data never returns to any state it visited: too few samples for a chain "
                         "at these class widths (use wider classes or more data)")
    ending = _ending_only(src_all, dst_all, keep, standstill_all)
    used = keep | ending
    kept_state = np.zeros(len(states), bool)
    kept_state[src_all[used]] = True
    kept_state[dst_all[ending]] = True
    new_id = np.cumsum(kept_state) - 1
    s, d, c, late = new_id[src_all[used]], new_id[dst_all[used]], counts.count[used], ending[used]
    order = np.lexsort((d, late, s))
    s, d, c, late = s[order], d[order], c[order].astype(np.int64), late[order]
    n = int(kept_state.sum())
    keys = states[kept_state]
    row_ptr = np.concatenate([[0], np.cumsum(np.bincount(s, minlength=n))]).astype(np.int64)
    free_end = row_ptr[:-1] + np.bincount(s[~late], minlength=n)
    cum = np.cumsum(c)
    cum_count = cum - np.repeat(np.concatenate([[0], cum[row_ptr[1:-1] - 1]]), np.diff(row_ptr))
    speed, gradient, mass = cls.centres(keys, counts.widths)
    standstill = speed == 0
    weight = np.bincount(d, weights=c * (~standstill[s] & standstill[d] & ~late), minlength=n)
    known = np.isin(counts.start_key, keys)
    weight[np.searchsorted(keys, counts.start_key[known])] += counts.start_count[known]
    if not weight.any():
        weight = np.bincount(s, weights=c * ~late, minlength=n)
    start = np.flatnonzero(weight)
    return Chain(counts.widths, keys, row_ptr, d.astype(np.int64), c, cum_count.astype(np.int64),
                 start.astype(np.int64), np.cumsum(weight[start]).astype(np.int64),
                 speed, gradient, mass, len(states), int(counts.count[~keep].sum()), free_end.astype(np.int64))
