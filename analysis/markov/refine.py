"""Score-guided refinement of a walk: it stays a walk the chain allows, and improves.

A move re-draws a window of the walk from the chain: from the state at second ``a`` a new walk is
drawn until it meets a state the old walk visits later in the window (second ``c``), and the old
walk goes on from there; or the walk's tail is drawn anew; or the walk starts in another start
state and is drawn until it meets the old walk's first window. Every transition of the result is one
of the chain's (the re-drawn part from its rows, the joins at equal states), so the result is
still a walk of the measured transitions. A splice that shortens the walk is continued from its
end by the chain, one that lengthens it is cut at the cycle's duration. Walks end at a stop
(`ending`): every draw is steered as the generator's are, the old walk is followed only while it
can still reach a stop by the end, and a proposal ending farther from a stop than the walk it
would replace is not taken. A move is kept when the
objective (`score_kernels.objective`, computed in two parts) falls; the kernel works on paths and statistics only.
"""

from __future__ import annotations

import numba
import numpy as np

from .chain import Chain
from .counting import TransitionCounts
from .criteria import _Q, _S, ALLOWANCE, scales
from .generate import GOLDEN, is_free, mix, path_statistics, plain_index, steered_end, steered_index, uniform
from .jit import helper, inlined_kernel, kernel
from .score_kernels import kinematic_objective, load_objective, path_loads

TAIL_SHARE = 0.2
"""Share of moves that re-draw the walk's tail."""
HEAD_SHARE = 0.1
"""Share of moves that start the walk in another start state (the first second of a stop) and
draw from there until the old walk's first window is met."""


@helper
def _next_state(row_ptr, dest, count, cum_count, s, r_after, ending, rng):
    """The state after ``s`` with ``r_after`` seconds of the walk left after it, ending at a stop
    as ``ending`` (`ending.Ending.as_tuple`) says; ``r_after`` < 0 past the walk's end. The callers
    write the plain draw out (a call per state that passes arrays costs their reference counts)."""
    free_end, steps_to_stop, reach_max, weight = ending
    if is_free(s, r_after, reach_max, weight):
        return dest[plain_index(row_ptr, free_end, cum_count, s, rng)]
    j = steered_index(count, row_ptr[s], steered_end(row_ptr, free_end, s, r_after, weight), dest, r_after,
                      steps_to_stop, weight, rng)
    return dest[j if j >= 0 else plain_index(row_ptr, free_end, cum_count, s, rng)]


@helper
def _kinematic_deviation(path, speed, gradient, mass, measured, scale, q_index, s_index, stats, out):
    path_statistics(path, speed, gradient, mass, stats)
    for i in range(out.shape[0]):
        out[i] = abs(stats[q_index[i], s_index[i]] - measured[q_index[i], s_index[i]]) / scale[i]


@helper
def _continue(current, n, k, c, row_ptr, dest, count, cum_count, ending, rng, proposal):
    """``proposal[k]`` is ``current[c]``: go on with the old walk after ``c`` while it can still
    reach a stop by the end, then with the chain, up to ``n`` states."""
    steps_to_stop = ending[1]
    while k < n - 1 and c < n - 1 and steps_to_stop[current[c + 1]] <= n - 2 - k:
        k += 1
        c += 1
        proposal[k] = current[c]
    s = proposal[min(k, n - 1)]
    free_end, reach_max, window = ending[0], ending[2], ending[3].shape[0]
    while k < n - 1:
        k += 1
        r_after = n - 1 - k
        if r_after >= window and reach_max[s] <= r_after:
            a = row_ptr[s]
            b = free_end[s]
            u = uniform(rng) * cum_count[b - 1]
            j = a
            while j < b - 1 and cum_count[j] <= u:
                j += 1
            s = dest[j]
        else:
            s = _next_state(row_ptr, dest, count, cum_count, s, r_after, ending, rng)
        proposal[k] = s


@helper
def _rejoin(current, n, first, last, k, s, row_ptr, dest, count, cum_count, ending, rng, limit, mark, proposal):
    """From state ``s`` at ``proposal[k]``, draw until a state of ``current[first..last]`` is met
    (within ``limit`` steps) and go on with the old walk from there; False if none is met."""
    if uniform(rng) < 0.5:
        for c in range(first, last + 1):
            mark[current[c]] = c
    else:
        for c in range(last, first - 1, -1):
            mark[current[c]] = c
    hit = mark[s]
    j = 0
    free_end, reach_max, window = ending[0], ending[2], ending[3].shape[0]
    while hit < 0 and j < limit:
        j += 1
        r_after = n - 1 - k - j
        if (r_after < 0 or (r_after >= window and reach_max[s] <= r_after)) and free_end[s] > row_ptr[s]:
            a = row_ptr[s]
            b = free_end[s]
            u = uniform(rng) * cum_count[b - 1]
            i = a
            while i < b - 1 and cum_count[i] <= u:
                i += 1
            s = dest[i]
        else:
            s = _next_state(row_ptr, dest, count, cum_count, s, r_after, ending, rng)
        if k + j < proposal.shape[0]:
            proposal[k + j] = s
        hit = mark[s]
    for c in range(first, last + 1):
        mark[current[c]] = -1
    if hit < 0:
        return False
    _continue(current, n, k + j, hit, row_ptr, dest, count, cum_count, ending, rng, proposal)
    return True


OBJECTIVE_KERNELS = (_kinematic_deviation, kinematic_objective)
"""The kinematic part of the objective, the first kernels `refine_walk`'s compile reaches:
`compile_objective` compiles them (``path_statistics`` inside them)."""
MOVE_KERNELS = (_rejoin, _continue)
"""The kernels a move calls: `compile_moves` compiles them (``_next_state`` inside them)."""


def kinematic_arrays(chain: Chain, counts: TransitionCounts) -> tuple:
    """`refine_walk`'s arguments for the kinematic part of its objective, in its order: the
    states' speed, gradient and mass, the measured statistics, their scales, the criteria's
    indices into them and their allowances."""
    return (chain.speed_mps, chain.gradient_pct, chain.mass_kg, counts.statistics,
            scales(counts.statistics, counts.widths), _Q, _S, ALLOWANCE)


def compile_objective(chain: Chain, counts: TransitionCounts) -> None:
    """Compile `OBJECTIVE_KERNELS` for the argument types `refine_walk` gives them for ``chain``
    and ``counts``, without compiling `refine_walk` (`precompile`)."""
    *arrays, kin_allowance = (numba.typeof(a) for a in kinematic_arrays(chain, counts))
    walk = numba.typeof(np.empty(0, np.int64))
    vector = numba.typeof(np.empty(0))
    _kinematic_deviation.compile((walk, *arrays, numba.typeof(np.empty((4, 4))), vector))
    kinematic_objective.compile((vector, kin_allowance))


def compile_moves(row_ptr, dest, count, cum_count, ending) -> None:
    """Compile `MOVE_KERNELS` for the argument types `refine_walk` gives them (through `_propose`),
    for a chain's arrays and ``ending`` (`ending.Ending.as_tuple`), without compiling `refine_walk`:
    numba caches them, and `refine_walk`'s own compile then loads them (`precompile`)."""
    walk = numba.typeof(np.empty(0, np.int64))  # current, mark, proposal: arrays refine_walk allocates
    rng = numba.typeof(np.empty(1, np.uint64))
    index = numba.types.int64
    chain = tuple(numba.typeof(a) for a in (row_ptr, dest, count, cum_count))
    _rejoin.compile((walk, index, index, index, index, index, *chain, numba.typeof(ending), rng, index, walk, walk))
    _continue.compile((walk, index, index, index, *chain, numba.typeof(ending), rng, walk))


@inlined_kernel
def _propose(current, n, row_ptr, dest, count, cum_count, start_state, start_cum, ending, max_window, mark, rng,
             proposal):
    """A re-drawn window, tail or head of ``current[:n]`` into ``proposal[:n]``; False if the
    re-drawn part found no way back into the walk."""
    # the kernel's own numba helpers are compiled apart from the helpers' (other options): min,
    # max and int() are written out here, so a first run compiles theirs once (issue 29)
    last = n - 1
    move = uniform(rng)
    window = 2 + np.int64(uniform(rng) * (max_window - 1))
    if move < HEAD_SHARE:
        u = uniform(rng) * start_cum[-1]
        j = 0
        while j < start_cum.shape[0] - 1 and start_cum[j] <= u:
            j += 1
        proposal[0] = start_state[j]
        head = np.int64(0)  # not the literal 0: one compiled _rejoin, not two
        return _rejoin(current, n, head, window if window < last else last, head, start_state[j], row_ptr, dest,
                       count, cum_count, ending, rng, window + window // 2, mark, proposal)
    if move < HEAD_SHARE + TAIL_SHARE:
        a = n - 2 - np.int64(uniform(rng) * (max_window if max_window < last else last))
        if a < 0:
            a = 0
        for k in range(a + 1):
            proposal[k] = current[k]
        _continue(current, n, a, last, row_ptr, dest, count, cum_count, ending, rng, proposal)
        return True
    a = np.int64(uniform(rng) * last)
    for k in range(a + 1):
        proposal[k] = current[k]
    return _rejoin(current, n, a + 1, a + window if a + window < last else last, a, current[a], row_ptr, dest, count,
                   cum_count, ending, rng, window + window // 2, mark, proposal)


@kernel
def refine_walk(path, row_ptr, dest, count, cum_count, start_state, start_cum, ending, speed, gradient, mass, measured, kin_scale, q_index, s_index,
                kin_allowance, use_loads, resistance, radius, speed_edges, torque_edges, share, range_scale,
                load_measured, load_scale, load_allowance, n_moves, max_window, temperature, seed, stream, trace):
    """Improve ``path`` in place over ``n_moves`` proposals; ``trace[m]`` the best objective after
    move m. Returns the best objective. A worse proposal is taken with probability exp(−Δ/T)
    (simulated annealing, T falling geometrically from ``temperature`` to a thousandth of it; 0 is
    greedy), so a walk can leave a local optimum; the best walk seen is the result."""
    n = path.shape[0]
    rng = np.empty(1, np.uint64)
    rng[0] = mix(np.uint64(seed) ^ mix(np.uint64(stream) + GOLDEN + GOLDEN))
    mark = np.empty(speed.shape[0], np.int64)
    for state in range(mark.shape[0]):  # not np.full: numba compiles its helper on a first run's way
        mark[state] = -1
    proposal = np.empty(n + 2 * max_window + 2, np.int64)
    stats = np.empty((4, 4))
    kin = np.empty(q_index.shape[0])
    loads = np.empty(load_measured.shape[0])
    torque = np.empty(n)
    power = np.empty(n)
    residence = np.empty((speed_edges.shape[0] - 1, torque_edges.shape[0] - 1))

    def value_of(p, threshold):
        """Objective of walk ``p``; its kinematic part alone when that reaches ``threshold``."""
        _kinematic_deviation(p, speed, gradient, mass, measured, kin_scale, q_index, s_index, stats, kin)
        value = kinematic_objective(kin, kin_allowance)
        if use_loads and value < threshold:
            path_loads(p, n, speed, mass, resistance, radius, speed_edges, torque_edges, share, range_scale,
                       loads, torque, power, residence)
            value += load_objective(loads, load_measured, load_scale, load_allowance)
        return value

    walk = path.copy()
    current = value_of(walk, np.inf)
    best = current
    cooling = 0.001 ** (1.0 / (n_moves if n_moves > 1 else 1))
    t = temperature
    for m in range(n_moves):
        if (_propose(walk, n, row_ptr, dest, count, cum_count, start_state, start_cum, ending, max_window, mark,
                     rng, proposal) and ending[1][proposal[n - 1]] <= ending[1][walk[n - 1]]):
            # taken if value < current + t·ln(1/u): Metropolis, exp(−Δ/t) > u
            threshold = current - t * np.log(1.0 - uniform(rng)) if t > 0 else current
            value = value_of(proposal[:n], threshold)
            if value < threshold:
                current = value
                for k in range(n):  # element by element: no shape-mismatch error for numba to compile
                    walk[k] = proposal[k]
                if value < best:
                    best = value
                    for k in range(n):
                        path[k] = walk[k]
        trace[m] = best
        t *= cooling
    return best
