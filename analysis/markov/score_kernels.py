"""numba kernels that score one walk: its load criteria and the objective of the refinement.

Each has a plain reference: the rainflow count is that of the ``rainflow`` package (ASTM E1049,
`analysis.loads.collectives.rainflow_cycles`), the load values those of `load_criteria.evaluate_loads`
through the loads module; tests compare them (and ``.py_func``) on the same walks.
"""

from __future__ import annotations

import numpy as np

from .jit import helper, inlined_kernel, kernel

EXPONENTS = np.arange(3, 9).astype(np.float64)
"""Wöhler exponents k of the damage-equivalent torque criteria (consecutive integers)."""
SHARES = np.array([0.05, 0.5, 0.95])
RPM_PER_RADPS = 60.0 / (2.0 * np.pi)
KINEMATIC_PENALTY = 10.0
"""Weight of a kinematic criterion's excess over its allowance: validity comes before closeness."""
LOAD_PENALTY = 1.0
"""Weight of a load criterion's excess over its allowance."""
LOAD_MARGIN = 0.9
"""Share of a gated load criterion's allowance from which its excess is penalised: the refinement
aims inside the allowance, so that its result does not end a hair beyond it."""
LOAD_WEIGHT = 0.1
"""Weight of the mean load deviation (over allowance) beside the score (15): within their
allowances the loads count half as much as the kinematic criteria, which define the cycle."""


@helper
def _add_powers(x, weight, exponents, out):
    """out[e] += weight · x^k for consecutive integer exponents k (one power, then products)."""
    p = weight * x ** exponents[0]
    out[0] += p
    for e in range(1, exponents.shape[0]):
        p *= x
        out[e] += p


@inlined_kernel
def rainflow_damage_sums(series, exponents, scale, out):
    """Σ count·(range/scale)^k over the rainflow cycles of ``series`` for each exponent k, into
    ``out`` (ASTM E1049 as the ``rainflow`` package counts: reversals, three-point stack, the
    residue as half cycles)."""
    n = series.shape[0]
    for e in range(exponents.shape[0]):
        out[e] = 0.0
    if n < 3:
        return
    stack = np.empty(n + 1)
    top = 0
    # reversals as rainflow.reversals yields them (plateaus skipped, first and last points kept)
    x_last = series[0]
    x = series[1]
    d_last = x - x_last
    stack[0] = x_last
    top = 1
    last_x_next = x
    for i in range(2, n + 1):
        is_point = False
        value = 0.0
        if i < n:
            x_next = series[i]
            last_x_next = x_next
            if x_next == x:
                continue
            d_next = x_next - x
            if d_last * d_next < 0:
                is_point = True
                value = x
            x_last = x
            x = x_next
            d_last = d_next
        else:
            is_point = True
            value = last_x_next
        if not is_point:
            continue
        stack[top] = value
        top += 1
        while top >= 3:
            big_x = abs(stack[top - 1] - stack[top - 2])
            big_y = abs(stack[top - 2] - stack[top - 3])
            if big_x < big_y:
                break
            if top == 3:
                _add_powers(big_y / scale, 0.5, exponents, out)
                stack[0] = stack[1]
                stack[1] = stack[2]
                top = 2
            else:
                _add_powers(big_y / scale, 1.0, exponents, out)
                stack[top - 3] = stack[top - 1]
                top -= 2
    for j in range(top - 1):
        _add_powers(abs(stack[j + 1] - stack[j]) / scale, 0.5, exponents, out)


@inlined_kernel
def _kth_smallest(work, k):
    """The ``k``-th smallest (0-based) of ``work``, which it reorders (Hoare's selection, O(n))."""
    lo, hi = 0, work.shape[0] - 1
    while lo < hi:
        pivot = work[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while work[i] < pivot:
                i += 1
            while work[j] > pivot:
                j -= 1
            if i <= j:
                work[i], work[j] = work[j], work[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return work[k]


@inlined_kernel
def time_quantiles(values, n_half, half_a, half_b, shares, out):
    """Time-weighted quantiles as `time_quantiles_sorted` gives them (``shares`` ascending), found
    by selection instead of a sort: the time up to a value v, F(v) = #(values ≤ v) − ½ #(half
    samples ≤ v), grows with v, so the quantile of share p is the smallest value with F ≥ p·T,
    which lies at the order statistic of rank ⌈p·T⌉ − 1 or a value or two above it. Three
    selections and counts of 1800 values cost a fifth of the sort (13 against 62 µs; every move of
    the refinement scores one walk), and a first run does not compile numba's sort (5 s)."""
    n = values.shape[0]
    work = np.empty(n)
    m = 0
    for k in range(n):  # NaN sorts last and is never <= v: selection runs on the rest
        if not np.isnan(values[k]):
            work[m] = values[k]
            m += 1
    total = n - 0.5 * n_half
    a = values[half_a]
    b = values[half_b]
    for q in range(shares.shape[0]):
        target = shares[q] * total
        if m == 0:
            out[q] = np.nan
            continue
        v = _kth_smallest(work[:m], min(max(int(np.ceil(target)) - 1, 0), m - 1))
        while True:
            count = 0
            above = np.inf
            for k in range(n):
                x = values[k]
                if x <= v:
                    count += 1
                elif x < above:
                    above = x
            halves = 0
            if n_half > 0 and a <= v:
                halves += 1
            if n_half > 1 and b <= v:
                halves += 1
            if count - 0.5 * halves >= target:
                out[q] = v
                break
            if above == np.inf:  # the share lies beyond the largest number: among the NaNs, if any
                out[q] = v if m == n else np.nan
                break
            v = above


@kernel
def time_quantiles_sorted(values, n_half, half_a, half_b, shares, out):
    """Time-weighted quantiles as `analysis.loads.summary.time_quantile` for 1 s samples of which
    the two at ``half_a`` and ``half_b`` stand for 0.5 s (a walk's ends). The value at the first
    sorted position whose cumulative time reaches the share does not depend on the order of tied
    values, so a plain sort gives the stable order's answer. The reference of `time_quantiles`."""
    ordered = np.sort(values)
    n = values.shape[0]
    total = n - 0.5 * n_half
    a = values[half_a]
    b = values[half_b]
    q = 0
    for k in range(n):
        if k < n - 1 and ordered[k + 1] == ordered[k]:
            continue
        v = ordered[k]
        halves = 0
        if n_half > 0 and a <= v:
            halves += 1
        if n_half > 1 and b <= v:
            halves += 1
        cumulative = (k + 1) - 0.5 * halves
        while q < shares.shape[0] and cumulative >= shares[q] * total:
            out[q] = v
            q += 1
        if q == shares.shape[0]:
            return
    while q < shares.shape[0]:
        out[q] = ordered[n - 1]
        q += 1


@helper
def path_loads(path, n, speed, mass, resistance, radius, speed_edges, torque_edges, share, range_scale, out,
               torque, power, residence):
    """Load criteria values (order of `load_criteria.LOAD_NAMES`) of the walk ``path[:n]`` into
    ``out``; ``torque`` and ``power`` (length ≥ n) and ``residence`` are work buffers."""
    distance = 0.0
    positive = 0.0
    negative = 0.0
    residence[:, :] = 0.0
    n_speed = speed_edges.shape[0] - 1
    n_torque = torque_edges.shape[0] - 1
    speed_step = (speed_edges[-1] - speed_edges[0]) / n_speed
    torque_step = (torque_edges[-1] - torque_edges[0]) / n_torque
    for k in range(n):
        s = path[k]
        if k == 0:
            accel = speed[path[1]] - speed[s]
        elif k == n - 1:
            accel = speed[s] - speed[path[k - 1]]
        else:
            accel = 0.5 * (speed[path[k + 1]] - speed[path[k - 1]])
        force = mass[s] * accel + resistance[s]
        torque[k] = force * radius
        power[k] = force * speed[s]
        d = 0.5 if (k == 0 or k == n - 1) else 1.0
        distance += speed[s] * d
        if power[k] > 0:
            positive += power[k] * d
        else:
            negative += power[k] * d
        rpm = speed[s] / radius * RPM_PER_RADPS
        i = int(np.floor((rpm - speed_edges[0]) / speed_step))
        j = int(np.floor((torque[k] - torque_edges[0]) / torque_step))
        residence[min(max(i, 0), n_speed - 1), min(max(j, 0), n_torque - 1)] += d
    km = distance / 1000.0
    out[0] = positive / 3.6e6 / km if km > 0 else np.nan
    out[1] = negative / 3.6e6 / km if km > 0 else np.nan
    sums = np.empty(EXPONENTS.shape[0])
    rainflow_damage_sums(torque[:n], EXPONENTS, range_scale, sums)
    equivalent = max(n - 1, 1)
    for e in range(EXPONENTS.shape[0]):
        out[2 + e] = range_scale * (sums[e] / equivalent) ** (1.0 / EXPONENTS[e])
    quantiles = np.empty(3)
    time_quantiles(power[:n], 2, 0, n - 1, SHARES, quantiles)
    for q in range(3):
        out[2 + EXPONENTS.shape[0] + q] = quantiles[q]
    total = 0.0
    for i in range(n_speed):
        for j in range(n_torque):
            total += residence[i, j]
    tvd = 0.0
    for i in range(n_speed):
        for j in range(n_torque):
            tvd += abs(residence[i, j] / total - share[i, j])
    out[out.shape[0] - 1] = 0.5 * tvd


@helper
def kinematic_objective(kin_deviation, kin_allowance):
    """The score (15) plus `KINEMATIC_PENALTY` times each criterion's excess over its allowance."""
    total = 0.0
    excess = 0.0
    for i in range(kin_deviation.shape[0]):
        r = kin_deviation[i] / kin_allowance[i]
        total += r
        if r > 1.0:
            excess += KINEMATIC_PENALTY * (r - 1.0)
    return total / kin_deviation.shape[0] + excess


@helper
def load_objective(load_values, load_measured, load_scale, load_allowance):
    """`LOAD_WEIGHT` times the mean load deviation over its allowance, plus `LOAD_PENALTY` times
    each excess over an allowance except the residence distance's (its own deviation): a 1800 s
    cycle cannot fill 400 speed × torque cells like hours of data (1800 s windows of the measured
    drive itself differ from the whole by 0.14–0.16), so it is scored, not forced."""
    last = load_values.shape[0] - 1
    total = 0.0
    excess = 0.0
    for i in range(load_values.shape[0]):
        if i == last:
            d = load_values[i]
        else:
            d = abs(load_values[i] - load_measured[i]) / load_scale[i]
        if not np.isfinite(d):
            d = 10.0
        r = d / load_allowance[i]
        total += r
        if r > LOAD_MARGIN and i != last:
            excess += LOAD_PENALTY * (r - LOAD_MARGIN)
    return LOAD_WEIGHT * total / load_values.shape[0] + excess


@kernel
def objective(kin_deviation, kin_allowance, load_values, load_measured, load_scale, load_allowance, use_loads):
    """What the refinement minimises: `kinematic_objective` plus, with loads, `load_objective`.
    Both are ≥ 0, so a walk whose kinematic part alone is too high needs no load computation.
    0 is a perfect copy of the measured statistics."""
    value = kinematic_objective(kin_deviation, kin_allowance)
    if use_loads:
        value += load_objective(load_values, load_measured, load_scale, load_allowance)
    return value
