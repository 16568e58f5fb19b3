"""Many candidates on the cycle set in one call: a numba ``prange`` over candidates, each running
the simulate stage's own kernel (`simulate.kernel.run_kernel`, with its driver, force split,
machine map and battery) on every cycle, then reducing its trace to the few numbers the search
needs (energy, distance, misses, peaks, the moving RMS torque and mean power over the thermal
windows). `batch_reference` is the same reduction in NumPy over `simulate.model.simulate_cycle`
traces; the tests hold the two together."""

from __future__ import annotations

import numba
import numpy as np

from ..simulate import kernel as K

M_ENERGY_J, M_DISTANCE_M, M_MISSED_S, M_PEAK_TORQUE_NM, M_PEAK_BATTERY_W = 0, 1, 2, 3, 4
M_MIN_SOC, M_STALLED, M_DURATION_S, M_PEAK_REGEN_W = 5, 6, 7, 8
M_WINDOWS = 9
"""Then, per thermal window, the largest moving RMS machine torque [Nm], then the largest moving
mean |machine power| [W]."""


def n_metrics(n_windows: int) -> int:
    return M_WINDOWS + 2 * n_windows


@numba.njit(cache=True)
def reduce_trace(out, n, dt, tolerance_mps, window_steps, metrics):
    """Reduce ``out[:, :n]`` (`simulate.kernel` columns by step) into ``metrics`` (columns M_*)."""
    energy, distance, missed, peak_t, peak_b, peak_r, min_soc = 0.0, 0.0, 0.0, 0.0, -np.inf, 0.0, np.inf
    for i in range(n):
        energy += out[K.C_P_BATT, i] * dt
        distance += out[K.C_DS, i]
        if out[K.C_LIMITED, i] > 0 and out[K.C_TARGET, i] - out[K.C_SPEED, i] > tolerance_mps:
            missed += dt
        t = abs(out[K.C_M_TORQUE, i])
        if t > peak_t:
            peak_t = t
        if out[K.C_P_BATT, i] > peak_b:
            peak_b = out[K.C_P_BATT, i]
        p_mech = out[K.C_M_TORQUE, i] * out[K.C_M_SPEED, i]
        if p_mech < peak_r:
            peak_r = p_mech
        if out[K.C_SOC, i] < min_soc:
            min_soc = out[K.C_SOC, i]
    metrics[M_ENERGY_J], metrics[M_DISTANCE_M], metrics[M_MISSED_S] = energy, distance, missed
    metrics[M_PEAK_TORQUE_NM], metrics[M_PEAK_BATTERY_W], metrics[M_MIN_SOC] = peak_t, peak_b, min_soc
    metrics[M_DURATION_S], metrics[M_PEAK_REGEN_W] = n * dt, -peak_r
    n_w = window_steps.shape[0]
    for w in range(n_w):
        k = min(max(window_steps[w], 1), max(n, 1))
        sq, pw, best_sq, best_pw = 0.0, 0.0, 0.0, 0.0
        for i in range(n):
            sq += out[K.C_M_TORQUE, i] ** 2
            pw += abs(out[K.C_M_TORQUE, i] * out[K.C_M_SPEED, i])
            if i >= k:
                sq -= out[K.C_M_TORQUE, i - k] ** 2
                pw -= abs(out[K.C_M_TORQUE, i - k] * out[K.C_M_SPEED, i - k])
            if i >= k - 1:
                best_sq, best_pw = max(best_sq, sq), max(best_pw, pw)
        metrics[M_WINDOWS + w] = np.sqrt(max(best_sq, 0.0) / k)
        metrics[M_WINDOWS + n_w + w] = best_pw / k


@numba.njit(cache=True, parallel=True)
def simulate_batch(time_based, starts, steps, t_end, row_pos, row_target, row_gradient, row_f_roll,
                   row_f_climb, row_mass, stop_starts, stop_pos, stop_time, load_time, aux, epto, obc,
                   params, ratios, n_ratios, map_speed, map_torque, map_eff, tolerance_mps, window_steps, metrics):
    """Every candidate (rows of ``params``, ``ratios``, ``map_speed``, ``map_torque``) on every cycle
    (rows ``starts[j]:starts[j+1]`` of the ``row_*`` arrays, stops ``stop_starts[j]:stop_starts[j+1]``)
    into ``metrics[candidate, cycle, :]``. ``row_f_roll``, ``row_f_climb`` and ``row_mass`` hold one
    row per candidate (its own mass). A run out of time (a stall) sets M_STALLED."""
    n_cand, n_cyc = params.shape[0], time_based.shape[0]
    for c in numba.prange(n_cand):
        p = params[c].copy()
        for j in range(n_cyc):
            a, b = starts[j], starts[j + 1]
            sa, sb = stop_starts[j], stop_starts[j + 1]
            p[K.P_T_END] = t_end[j]
            size = steps[j]
            while True:
                out = np.empty((K.N_COLUMNS, size))
                n = K.run_kernel(time_based[j] > 0, row_pos[a:b], row_target[a:b], row_gradient[a:b],
                                 row_f_roll[c, a:b], row_f_climb[c, a:b], row_mass[c, a:b], stop_pos[sa:sb],
                                 stop_time[sa:sb], load_time, aux, epto, obc, p, ratios[c, :n_ratios[c]],
                                 map_speed[c], map_torque[c], map_eff, out)
                if n != -1:
                    break
                size *= 2
            m = metrics[c, j]
            if n < 0:
                m[:] = np.nan
                m[M_STALLED] = 1.0
            else:
                reduce_trace(out, n, p[K.P_DT], tolerance_mps, window_steps, m)
                m[M_STALLED] = 0.0


def batch_reference(traces, dt: float, tolerance_mps: float, window_steps: np.ndarray) -> np.ndarray:
    """The same metrics in NumPy from `simulate.model.simulate_cycle` traces (one per cycle)."""
    rows = []
    for trace in traces:
        torque = trace["machine_torque_nm"].to_numpy()
        power = torque * trace["machine_speed_radps"].to_numpy()
        m = np.zeros(n_metrics(len(window_steps)))
        m[M_ENERGY_J] = trace["battery_terminal_power_w"].sum() * dt
        m[M_DISTANCE_M] = trace["step_distance_m"].sum()
        deficit = trace["target_speed_mps"] - trace["speed_mps"]
        m[M_MISSED_S] = float(((trace["traction_limited"] > 0) & (deficit > tolerance_mps)).sum()) * dt
        m[M_PEAK_TORQUE_NM] = np.abs(torque).max()
        m[M_PEAK_BATTERY_W] = trace["battery_terminal_power_w"].max()
        m[M_MIN_SOC] = trace["soc"].min()
        m[M_DURATION_S] = len(trace) * dt
        m[M_PEAK_REGEN_W] = -min(power.min(), 0.0)
        for w, k in enumerate(window_steps):
            k = int(min(max(k, 1), len(trace)))
            kernel = np.ones(k)
            m[M_WINDOWS + w] = np.sqrt(np.convolve(torque ** 2, kernel, "valid").max() / k)
            m[M_WINDOWS + len(window_steps) + w] = np.convolve(np.abs(power), kernel, "valid").max() / k
        rows.append(m)
    return np.array(rows)
