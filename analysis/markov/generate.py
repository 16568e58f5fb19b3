"""Monte Carlo generation: walks through the chain at 1 Hz, in numba, seeded per candidate.

Candidate ``i`` of seed ``S`` draws its random numbers from a SplitMix64 stream seeded by
(S, i) alone, so a candidate is the same whichever batch it was drawn in, and the best of
10 000 can be drawn again from its index without keeping 10 000 paths in memory.

With ``update_counts`` a walk takes each transition out of the counts it draws from (drawing
without replacement from the measured transitions, as the paper updates its matrices after each
selection); a row used up is refilled with its measured counts. Over a walk as long as the data
this reproduces the measured statistics exactly; over 1800 s of hours of data it slightly narrows
the spread between candidates (finite-population factor) and leaves their mean unchanged.

Every walk ends at a stop (`ending`): its last seconds are drawn from the chain conditioned on
standing still at the end. Until then a draw is the plain one, so a walk is the one drawn before
walks ended at a stop up to where the ending first steers it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .. import kinematics
from ..errors import UserError
from .chain import Chain, build_chain
from .counting import TransitionCounts
from .ending import WINDOW_S, Ending, ending_for, free_ending
from .jit import helper, inlined_kernel, kernel

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX1 = np.uint64(0xBF58476D1CE4E5B9)
MIX2 = np.uint64(0x94D049BB133111EB)
TWO_POW_MINUS_53 = 1.0 / 9007199254740992.0


class GenerationError(UserError):
    pass


@helper
def mix(z):
    z = (z ^ (z >> np.uint64(30))) * MIX1
    z = (z ^ (z >> np.uint64(27))) * MIX2
    return z ^ (z >> np.uint64(31))


@helper
def uniform(rng):
    """Next uniform number in [0, 1) of the SplitMix64 stream in ``rng`` (uint64[1])."""
    rng[0] += GOLDEN
    return np.float64(mix(rng[0]) >> np.uint64(11)) * TWO_POW_MINUS_53


@helper
def _ending_factor(state, r_after, steps_to_stop, weight):
    """Weight of arriving in ``state`` with ``r_after`` seconds left (`ending.Ending`)."""
    if r_after < weight.shape[0]:
        return weight[r_after, state]
    return 1.0 if steps_to_stop[state] <= r_after else 0.0


@helper
def steered_index(weights, a, b, dest, r_after, steps_to_stop, weight, rng):
    """Transition ``a <= j < b`` drawn with ``weights[j]`` times its ending factor; −1 if all are 0."""
    total = 0.0
    for j in range(a, b):
        total += weights[j] * _ending_factor(dest[j], r_after, steps_to_stop, weight)
    if not total > 0.0:
        return -1
    u = uniform(rng) * total
    acc = 0.0
    for j in range(a, b):
        w = weights[j] * _ending_factor(dest[j], r_after, steps_to_stop, weight)
        acc += w
        if w > 0.0 and acc > u:
            return j
    for j in range(b - 1, a - 1, -1):
        if weights[j] * _ending_factor(dest[j], r_after, steps_to_stop, weight) > 0.0:
            return j
    return -1


@helper
def is_free(s, r_after, reach_max, weight):
    """True when no transition out of ``s`` is constrained with ``r_after`` seconds left."""
    return r_after < 0 or (r_after >= weight.shape[0] and reach_max[s] <= r_after)


@helper
def steered_end(row_ptr, free_end, s, r_after, weight):
    """End of the transitions out of ``s`` a steered draw chooses from: its ending ones too in the
    window."""
    return row_ptr[s + 1] if r_after < weight.shape[0] else free_end[s]


@helper
def plain_index(row_ptr, free_end, cum_count, s, rng):
    """Transition out of ``s`` on a walk's way, drawn in proportion to its count."""
    a = row_ptr[s]
    b = free_end[s] if free_end[s] > a else row_ptr[s + 1]
    u = uniform(rng) * cum_count[b - 1]
    j = a
    while j < b - 1 and cum_count[j] <= u:
        j += 1
    return j


@inlined_kernel
def _draw(row_ptr, dest, count, cum_count, free_end, steps_to_stop, reach_max, weight, s, r_after, update,
          remaining, rng):
    """Transition out of ``s`` with ``r_after`` seconds left after it, drawn from the remaining
    counts with ``update`` and steered to a stop where the ending says so (`walk`'s slow path)."""
    a = row_ptr[s]
    free = is_free(s, r_after, reach_max, weight)
    b = free_end[s] if free else steered_end(row_ptr, free_end, s, r_after, weight)
    if not update:
        j = steered_index(count, a, b, dest, r_after, steps_to_stop, weight, rng)
        return j if j >= 0 else plain_index(row_ptr, free_end, cum_count, s, rng)
    total = 0
    for j in range(a, b):
        total += remaining[j]
    if total == 0:
        for j in range(a, b):
            remaining[j] = count[j]
            total += count[j]
    if free:
        u = uniform(rng) * total
        acc = 0
        j = a
        while j < b - 1:
            acc += remaining[j]
            if acc > u:
                break
            j += 1
    else:
        j = steered_index(remaining, a, b, dest, r_after, steps_to_stop, weight, rng)
        if j < 0:
            for i in range(a, b):
                remaining[i] = count[i]
            j = steered_index(remaining, a, b, dest, r_after, steps_to_stop, weight, rng)
        if j < 0:
            j = plain_index(row_ptr, free_end, cum_count, s, rng)
    if remaining[j] > 0:
        remaining[j] -= 1
    return j


@inlined_kernel
def walk(row_ptr, dest, count, cum_count, start_state, start_cum, seed, index, update, remaining, touched,
          path, free_end, steps_to_stop, reach_max, weight):
    """One candidate: states ``path[0..n-1]`` from a start state, one transition per second,
    ending at a stop (`ending.Ending`: ``free_end``, ``steps_to_stop``, ``reach_max``, ``weight``).
    The plain draw is written out here: a call per second that passes arrays costs their
    reference counts (four times the walk's time)."""
    rng = np.empty(1, np.uint64)
    rng[0] = mix(np.uint64(seed) ^ mix(np.uint64(index) + GOLDEN))
    u = uniform(rng) * start_cum[-1]
    j = 0
    while j < start_cum.shape[0] - 1 and start_cum[j] <= u:
        j += 1
    s = start_state[j]
    path[0] = s
    n = path.shape[0]
    window = weight.shape[0]
    n_touched = 0
    for k in range(1, n):
        r_after = n - 1 - k
        if not update and r_after >= window and reach_max[s] <= r_after:
            a = row_ptr[s]
            b = free_end[s]
            u = uniform(rng) * cum_count[b - 1]
            j = a
            while j < b - 1 and cum_count[j] <= u:
                j += 1
        elif not update and r_after < window:
            a = row_ptr[s]
            b = row_ptr[s + 1]
            total = 0.0
            for i in range(a, b):
                total += count[i] * weight[r_after, dest[i]]
            j = -1
            if total > 0.0:
                u = uniform(rng) * total
                acc = 0.0
                for i in range(a, b):
                    w = count[i] * weight[r_after, dest[i]]
                    acc += w
                    if w > 0.0:
                        j = i
                        if acc > u:
                            break
            if j < 0:
                j = plain_index(row_ptr, free_end, cum_count, s, rng)
        else:
            j = _draw(row_ptr, dest, count, cum_count, free_end, steps_to_stop, reach_max, weight, s, r_after,
                      update, remaining, rng)
            if update:
                touched[n_touched] = j
                n_touched += 1
        s = dest[j]
        path[k] = s
    for t in range(n_touched):
        remaining[touched[t]] = count[touched[t]]


@helper
def path_statistics(path, speed, gradient, mass, out):
    """(mean, std, min, max) of speed, gradient, acceleration (1 Hz speed difference) and mass
    along ``path`` into ``out[4, 4]`` (population std)."""
    for q in range(4):
        n = path.shape[0] if q != 2 else path.shape[0] - 1
        total = 0.0
        total_sq = 0.0
        low = np.inf
        high = -np.inf
        for k in range(n):
            if q == 0:
                x = speed[path[k]]
            elif q == 1:
                x = gradient[path[k]]
            elif q == 2:
                x = speed[path[k + 1]] - speed[path[k]]
            else:
                x = mass[path[k]]
            total += x
            total_sq += x * x
            low = min(low, x)
            high = max(high, x)
        mean = total / max(n, 1)
        out[q, 0] = mean
        out[q, 1] = np.sqrt(max(total_sq / max(n, 1) - mean * mean, 0.0))
        out[q, 2] = low
        out[q, 3] = high


def path_statistics_reference(path, speed, gradient, mass) -> np.ndarray:
    """NumPy reference of `path_statistics`."""
    series = [speed[path], gradient[path], np.diff(speed[path]), mass[path]]
    return np.array([[x.mean(), x.std(), x.min(), x.max()] for x in series])


@kernel
def batch(row_ptr, dest, count, cum_count, start_state, start_cum, speed, gradient, mass, seed, first_index,
           n_steps, update, stats, paths, free_end, steps_to_stop, reach_max, weight):
    """Candidates ``first_index …`` : statistics into ``stats[i]``; paths into ``paths[i]`` when
    ``paths`` has rows (otherwise one path buffer is reused); each ends as ``free_end``,
    ``steps_to_stop``, ``reach_max`` and ``weight`` (`ending.Ending`) say."""
    keep = paths.shape[0] > 0
    buffer = np.empty(n_steps, np.int64)
    remaining = count.copy()
    touched = np.empty(n_steps, np.int64)
    for i in range(stats.shape[0]):
        path = paths[i] if keep else buffer
        walk(row_ptr, dest, count, cum_count, start_state, start_cum, seed, first_index + i, update,
              remaining, touched, path, free_end, steps_to_stop, reach_max, weight)
        path_statistics(path, speed, gradient, mass, stats[i])


def _as_chain(counts) -> Chain:
    return counts if isinstance(counts, Chain) else build_chain(counts)


def _steps(duration_s: float) -> int:
    if not np.isfinite(duration_s) or duration_s < 2:
        raise GenerationError(f"cycle duration must be at least 2 s, got {duration_s}")
    return int(round(duration_s)) + 1


def _check_seed(seed: int) -> int:
    if not 0 <= int(seed) < 2**63:
        raise GenerationError(f"seed must be a non-negative integer, got {seed}")
    return int(seed)


SHORTEST_ENDING_S = 4 * WINDOW_S
"""Shortest cycle [s] that ends at a stop: conditioning a short walk's last 120 s on a stop keeps
walks of short logs standing at their first stop throughout (300 s cycles of a CAN-only log)."""


def walk_ending(chain: Chain, duration_s: float, end_at_stop: bool = True) -> Ending:
    """How walks of ``duration_s`` [s] through ``chain`` end: at a stop (`ending`; cycles of at
    least `SHORTEST_ENDING_S`), or anywhere."""
    if end_at_stop and duration_s >= SHORTEST_ENDING_S:
        return ending_for(chain, _steps(duration_s))
    return free_ending(chain)


def run_batch(chain: Chain, duration_s: float, n_candidates: int, seed: int, first_index: int = 0,
              update_counts: bool = False, keep_paths: bool = False, ending: Ending | None = None):
    """Statistics (n, 4, 4) of candidates ``first_index …``, and their paths if ``keep_paths``;
    walks end as ``ending`` says (None: at a stop, `walk_ending`)."""
    n_steps = _steps(duration_s)
    ending = ending if ending is not None else walk_ending(chain, duration_s)
    stats = np.empty((n_candidates, 4, 4))
    paths = np.empty((n_candidates if keep_paths else 0, n_steps), np.int64)
    batch(chain.row_ptr, chain.dest, chain.count, chain.cum_count, chain.start_state, chain.start_cum,
           chain.speed_mps, chain.gradient_pct, chain.mass_kg, _check_seed(seed), int(first_index), n_steps,
           bool(update_counts), stats, paths, *ending.as_tuple())
    return stats, paths


def cycle_frame(chain: Chain, path: np.ndarray) -> pd.DataFrame:
    """A candidate as a 1 Hz cycle: time [s], class-centre speed [m/s], acceleration [m/s²] as the
    kinematics stage estimates it from a speed trace (central difference at 1 Hz, one-sided at the
    ends), gradient [%], mass [kg], distance at constant speed per second [m].

    **[choice]** Not the forward difference: a walk flipping between two speed classes (a cruise at
    a class boundary, as the data did) would then carry ±one class per second of acceleration, and
    its wheel torque a rainflow cycle of m·w each second that the measured drive, whose acceleration
    the kinematics stage estimates from its speed, does not have (+50 % damage-equivalent torque on
    synthetic urban data, docs/cycles.md). The kinematic criteria still use 1 Hz differences."""
    speed = chain.speed_mps[path]
    time = np.arange(len(path), dtype=float)
    return pd.DataFrame({
        "time_s": time,
        "speed_mps": speed,
        "accel_mps2": kinematics.acceleration_mps2(time, speed) if len(path) > 1 else np.zeros(len(path)),
        "gradient_pct": chain.gradient_pct[path],
        "mass_kg": chain.mass_kg[path],
        "distance_m": np.concatenate([[0.0], np.cumsum(speed[:-1])]),
    })


@dataclass
class Candidates:
    """Generated candidates: ``paths[i]`` state ids of candidate ``first_index + i`` of ``seed``."""

    chain: Chain
    paths: np.ndarray
    statistics: np.ndarray
    seed: int
    first_index: int
    update_counts: bool

    def __len__(self) -> int:
        return len(self.paths)

    def frame(self, i: int) -> pd.DataFrame:
        return cycle_frame(self.chain, self.paths[i])


def generate(counts: TransitionCounts | Chain, duration_s: float = 1800.0, n_candidates: int = 100,
             seed: int = 0, update_counts: bool = False, first_index: int = 0,
             end_at_stop: bool = True) -> Candidates:
    """Draw ``n_candidates`` cycles of ``duration_s`` [s] at 1 Hz, starting at standstill and, with
    ``end_at_stop``, ending at a stop (`ending`)."""
    chain = _as_chain(counts)
    stats, paths = run_batch(chain, duration_s, n_candidates, seed, first_index, update_counts, keep_paths=True,
                             ending=walk_ending(chain, duration_s, end_at_stop))
    return Candidates(chain, paths, stats, int(seed), int(first_index), bool(update_counts))
