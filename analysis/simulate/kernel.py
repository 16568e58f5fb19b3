"""Numba core of the longitudinal simulation: a forward model with a fixed time step.

One step: the driver (state machine + speed controller) asks for a wheel force, the powertrain
splits it into machine traction/recuperation and friction brake within its limits, equation (1)
gives the acceleration, and the DC bus (inverter, auxiliaries, ePTO, OBC) draws from a battery with
internal resistance. The kernel is written once; ``run_kernel.py_func`` is the same code run by the
Python interpreter (the reference the tests compare against). Road forces (2)-(3) arrive
precomputed per cycle row from `analysis.road_load`, aero (4) as its coefficient [N/(m/s)^2].
"""

from __future__ import annotations

import math

import numba
import numpy as np

# --- parameter vector indices (see `analysis.simulate.powertrain.pack_parameters`)
P_DT = 0                # time step [s]
P_AERO = 1              # F_aero / v^2 [N s^2/m^2]
P_ROT_MASS = 2          # equivalent rotating mass [kg]
P_WHEEL_RADIUS = 3      # [m]
P_GEAR_EFF = 4          # machine -> wheel efficiency [-]
P_MAX_TORQUE = 5        # machine [Nm]
P_MAX_POWER = 6         # machine [W]
P_MAX_SPEED = 7         # machine [rad/s]
P_MAX_RECUP = 8         # machine shaft power while recuperating [W]
P_INV_EFF = 9           # [-]
P_MACHINE_EFF = 10      # constant efficiency when no map is given [-]
P_OCV = 11              # battery open-circuit voltage [V]
P_RESISTANCE = 12       # battery internal resistance [ohm]
P_CHARGE_C = 13         # battery capacity [C]
P_SOC0 = 14             # initial state of charge [-]
P_CTRL_TAU = 15         # speed controller time constant [s]
P_ACC_MAX = 16          # driver's largest wish for acceleration [m/s^2]
P_DEC_BRAKE = 17        # planned braking deceleration [m/s^2]
P_BRAKE_MAX = 18        # largest deceleration the brakes give [m/s^2]
P_T_END = 19            # safety end of simulated time [s]
P_MIN_SOC = 20          # [-]
N_PARAMETERS = 21

# --- driver states
STANDSTILL, DRIVE, COAST, BRAKE = 0, 1, 2, 3
COAST_HOLD = 0.5
"""Once coasting towards a lower target, the driver keeps coasting while the deceleration still
needed is at least this share of the coasting deceleration; below it (the lower target is far or
the truck already slow) the driver drives again instead of rolling down to it."""

# --- output rows of ``out``, one column per step (values at the step's start, energies over the step)
C_TIME, C_DIST, C_SPEED, C_TARGET, C_ACCEL, C_STATE, C_GEAR = 0, 1, 2, 3, 4, 5, 6
C_F_TRAC, C_F_FRIC, C_F_ROLL, C_F_CLIMB, C_F_AERO = 7, 8, 9, 10, 11
C_M_SPEED, C_M_TORQUE, C_LIMITED, C_SOC, C_CURRENT, C_P_BATT = 12, 13, 14, 15, 16, 17
C_E_TRAC, C_E_FRIC, C_E_GEAR_LOSS, C_E_MACHINE_LOSS, C_E_INV_LOSS = 18, 19, 20, 21, 22
C_E_BATT_LOSS, C_E_BATT, C_E_AUX, C_E_EPTO, C_E_OBC, C_DS, C_GRADIENT = 23, 24, 25, 26, 27, 28, 29
N_COLUMNS = 30


@numba.njit(cache=True)
def interp_bilinear(x, y, xs, ys, table):
    """Bilinear interpolation in a regular table, clamped at its edges."""
    nx, ny = xs.shape[0], ys.shape[0]
    x = min(max(x, xs[0]), xs[nx - 1])
    y = min(max(y, ys[0]), ys[ny - 1])
    i = min(max(np.searchsorted(xs, x) - 1, 0), nx - 2) if nx > 1 else 0
    j = min(max(np.searchsorted(ys, y) - 1, 0), ny - 2) if ny > 1 else 0
    if nx == 1 and ny == 1:
        return table[0, 0]
    tx = (x - xs[i]) / (xs[i + 1] - xs[i]) if nx > 1 else 0.0
    ty = (y - ys[j]) / (ys[j + 1] - ys[j]) if ny > 1 else 0.0
    i1 = i + 1 if nx > 1 else i
    j1 = j + 1 if ny > 1 else j
    return ((1 - tx) * (1 - ty) * table[i, j] + tx * (1 - ty) * table[i1, j]
            + (1 - tx) * ty * table[i, j1] + tx * ty * table[i1, j1])


@numba.njit(cache=True)
def machine_efficiency(speed_radps, torque_nm, p, map_speed, map_torque, map_eff):
    """Machine efficiency [-] at an operating point: the map (speed [rad/s] x |torque| [Nm]) or constant."""
    if map_speed.shape[0] == 0:
        return p[P_MACHINE_EFF]
    return interp_bilinear(speed_radps, abs(torque_nm), map_speed, map_torque, map_eff)


@numba.njit(cache=True)
def machine_torque_limit_nm(speed_radps, p):
    """Largest machine torque [Nm] at a speed [rad/s]: constant torque, then constant power."""
    if speed_radps > p[P_MAX_SPEED]:
        return 0.0
    if speed_radps * p[P_MAX_TORQUE] <= p[P_MAX_POWER]:
        return p[P_MAX_TORQUE]
    return p[P_MAX_POWER] / speed_radps


@numba.njit(cache=True)
def split_wheel_force(force_n, speed_mps, p, ratios, map_speed, map_torque, map_eff):
    """Split a wheel force wish [N] into (machine force at the wheel [N], friction brake force [N],
    gear index, limited flag). Motoring: the feasible gear with the least electric power (ties go to
    the higher gear), else the
    gear with the most force. Braking: the gear that recuperates most; the rest goes to friction."""
    r, eta_g = p[P_WHEEL_RADIUS], p[P_GEAR_EFF]
    best_gear, best_force, best_cost = 0, 0.0, np.inf
    max_gear, max_force = ratios.shape[0] - 1, -1.0
    for g in range(ratios.shape[0] - 1, -1, -1):
        omega = max(speed_mps, 0.05) / r * ratios[g]
        t_lim = machine_torque_limit_nm(omega, p)
        if force_n >= 0.0:
            force_avail = t_lim * ratios[g] * eta_g / r
            if force_avail > max_force:
                max_gear, max_force = g, force_avail
            if force_avail >= force_n:
                torque = force_n * r / (ratios[g] * eta_g)
                cost = torque * omega / machine_efficiency(omega, torque, p, map_speed, map_torque, map_eff)
                if cost < best_cost:
                    best_gear, best_force, best_cost = g, force_n, cost
        else:
            t_lim = min(t_lim, p[P_MAX_RECUP] / omega)
            force_avail = t_lim * ratios[g] / (r * eta_g)
            force = min(-force_n, force_avail)
            torque = force * r * eta_g / ratios[g]
            cost = -torque * omega * machine_efficiency(omega, torque, p, map_speed, map_torque, map_eff)
            if cost < best_cost:
                best_gear, best_force, best_cost = g, -force, cost
    if force_n >= 0.0:
        if best_cost == np.inf:
            return max(max_force, 0.0), 0.0, max_gear, 1
        return best_force, 0.0, best_gear, 0
    return best_force, force_n - best_force, best_gear, 0


@numba.njit(cache=True)
def battery_current_a(dc_power_w, p):
    """Current [A] for a terminal power [W]: P = U_oc I - I^2 R solved for I (discharge > 0);
    a power beyond U_oc^2/(4R) is clipped there."""
    u, res = p[P_OCV], p[P_RESISTANCE]
    if res <= 0.0:
        return dc_power_w / u
    disc = u * u - 4.0 * res * dc_power_w
    if disc < 0.0:
        disc = 0.0
    return (u - math.sqrt(disc)) / (2.0 * res)


@numba.njit(cache=True)
def _interp(x, xs, ys):
    n = xs.shape[0]
    if n == 1 or x <= xs[0]:
        return ys[0]
    if x >= xs[n - 1]:
        return ys[n - 1]
    i = np.searchsorted(xs, x) - 1
    w = (x - xs[i]) / (xs[i + 1] - xs[i])
    return ys[i] + w * (ys[i + 1] - ys[i])


@numba.njit(cache=True)
def _bracket(x, xs, i):
    """``_interp``'s interval for ``x`` (``xs[i] < x <= xs[i + 1]``, ``xs[0] < x < xs[-1]``),
    searched forward from ``i``: a run's query times never decrease, so each step moves the
    cursor by a row or two instead of a binary search over the whole cycle."""
    while xs[i + 1] < x:
        i += 1
    return i


@numba.njit(cache=True)
def _interp_cursor(x, xs, ys, i):
    """(``_interp(x, xs, ys)``, cursor): the same value, bit for bit, found from cursor ``i``
    (an interval below ``x`` of an earlier, smaller query; 0 at first)."""
    n = xs.shape[0]
    if n == 1 or x <= xs[0]:
        return ys[0], i
    if x >= xs[n - 1]:
        return ys[n - 1], i
    i = _bracket(x, xs, i)
    w = (x - xs[i]) / (xs[i + 1] - xs[i])
    return ys[i] + w * (ys[i + 1] - ys[i]), i


@numba.njit(cache=True)
def _look_ahead_decel(s, v, k, row_pos, row_target, stop_pos, next_stop, horizon_m):
    """Deceleration [m/s^2] needed to reach the next lower target speed or the next stop ahead,
    and whether that constraint is the stop."""
    need, is_stop = 0.0, False
    for j in range(k + 1, row_pos.shape[0]):
        d = row_pos[j] - s
        if d > horizon_m:
            break
        if row_target[j] < v and d > 0.0:
            a = (v * v - row_target[j] * row_target[j]) / (2.0 * d)
            if a > need:
                need = a
    if next_stop < stop_pos.shape[0]:
        d = stop_pos[next_stop] - s
        if d <= horizon_m:
            a = v * v / (2.0 * max(d, 1e-6))
            if a >= need:
                need, is_stop = a, True
    return need, is_stop


@numba.njit(cache=True)
def run_kernel(time_based, row_pos, row_target, row_gradient, row_f_roll, row_f_climb, row_mass,
               stop_pos, stop_time, load_time, aux_w, epto_w, obc_w,
               p, ratios, map_speed, map_torque, map_eff, out):
    """Simulate the whole cycle into ``out`` (rows C_*, a column per step: each quantity
    contiguous, so the trace frame takes them without a copy); return the number of steps, -1
    when ``out`` is too short, -2 when the time ``P_T_END`` ran out first.

    Distance-based (``time_based`` False): rows are segments starting at ``row_pos`` [m] with a
    constant target speed [m/s], gradient and mass; the truck stops at ``stop_pos`` [m] for
    ``stop_time`` [s]. Time-based: rows are samples of a speed trace at ``row_pos`` [s], followed
    by a deadbeat controller (forces interpolated at mid-step).
    """
    dt = p[P_DT]
    m_rot = p[P_ROT_MASS]
    n_rows = row_pos.shape[0]
    end_pos = row_pos[n_rows - 1]
    t, s, v, soc = 0.0, row_pos[0] if not time_based else 0.0, 0.0, p[P_SOC0]
    if time_based:
        t = row_pos[0]
        v = row_target[0]
    k, next_stop, state, timer = 0, 0, DRIVE, 0.0
    n = 0
    at_mid, at_start, at_end, at_load = 0, 0, 0, 0  # interpolation cursors (times only grow)
    while True:
        if time_based:
            if t >= end_pos - 1e-9:
                break
        else:
            if s >= end_pos - 1e-6 and next_stop >= stop_pos.shape[0]:
                break
        if n >= out.shape[1]:
            return -1
        if t >= p[P_T_END]:
            return -2
        if time_based:
            tm = t + 0.5 * dt
            f_roll, at_mid = _interp_cursor(tm, row_pos, row_f_roll, at_mid)
            f_climb, at_mid = _interp_cursor(tm, row_pos, row_f_climb, at_mid)
            mass, at_mid = _interp_cursor(tm, row_pos, row_mass, at_mid)
            grad, at_mid = _interp_cursor(tm, row_pos, row_gradient, at_mid)
            target, at_start = _interp_cursor(t, row_pos, row_target, at_start)
            target_next, at_end = _interp_cursor(t + dt, row_pos, row_target, at_end)
        else:
            while k + 1 < n_rows and row_pos[k + 1] <= s + 1e-9:
                k += 1
            f_roll, f_climb, mass, grad = row_f_roll[k], row_f_climb[k], row_mass[k], row_gradient[k]
            target = row_target[k]
            target_next = target
        m_eff = mass + m_rot
        f_aero = p[P_AERO] * v * v
        f_res = f_roll + f_climb + f_aero

        # ---- driver
        while (not time_based and state != STANDSTILL and next_stop < stop_pos.shape[0]
               and stop_pos[next_stop] - s <= 1e-3 and v <= 1e-6):
            if stop_time[next_stop] < 0.5 * dt:
                next_stop += 1
            else:
                state, timer = STANDSTILL, 0.0
        if time_based and target_next <= 1e-6 and v <= 1e-6:
            state = STANDSTILL
        elif time_based:
            state = DRIVE
        if state == STANDSTILL:
            a_wish = 0.0
        elif time_based:
            a_wish = (target_next - v) / dt
        else:
            a_ctrl = min((target - v) / max(p[P_CTRL_TAU], dt), p[P_ACC_MAX])
            horizon = v * v / (2.0 * 0.05) + 50.0
            need, is_stop = _look_ahead_decel(s, v, k, row_pos, row_target, stop_pos, next_stop, horizon)
            a_coast = -f_res / m_eff
            if need >= p[P_DEC_BRAKE] or (is_stop and need > 0.0 and v < 1.0):
                state, a_wish = BRAKE, min(a_ctrl, -need)
            elif need > 0.0 and (need >= -a_coast or (state == COAST and need >= COAST_HOLD * -a_coast)):
                state, a_wish = COAST, min(a_ctrl, a_coast)
            else:
                state, a_wish = DRIVE, a_ctrl
        a_wish = max(a_wish, -p[P_BRAKE_MAX])

        # ---- powertrain and vehicle
        limited = 0
        if state == STANDSTILL:
            f_trac, f_fric, gear, a, ds, v_new = 0.0, 0.0, 0, 0.0, 0.0, 0.0
        else:
            if state == COAST and a_wish == a_coast:
                f_wish = 0.0
            else:
                f_wish = m_eff * a_wish + f_res
            f_trac, f_fric, gear, limited = split_wheel_force(f_wish, v, p, ratios, map_speed, map_torque, map_eff)
            if soc <= p[P_MIN_SOC] and f_trac > 0.0:
                f_trac, limited = 0.0, 1
            a = (f_trac + f_fric - f_res) / m_eff
            v_new = v + a * dt
            ds = 0.5 * (v + v_new) * dt
            to_stop = stop_pos[next_stop] - s if (not time_based and next_stop < stop_pos.shape[0]) else np.inf
            if ds >= to_stop or (v_new <= 0.0 and to_stop < 1.0):
                ds, v_new = max(to_stop, 0.0), 0.0
                a = -v * v / (2.0 * ds) if ds > 0.0 else -v / dt
            elif v_new < 0.0:
                a, v_new = -v / dt, 0.0
                ds = 0.5 * v * dt
            f_total = m_eff * a + f_res
            if f_total != f_trac + f_fric:
                f_fric = min(f_total - f_trac, 0.0)
                f_trac = f_total - f_fric
        # machine operating point over the step (mean speed of the step)
        v_mean = ds / dt
        omega = v_mean / p[P_WHEEL_RADIUS] * ratios[gear]
        e_wheel = f_trac * ds
        if f_trac >= 0.0:
            torque = f_trac * p[P_WHEEL_RADIUS] / (ratios[gear] * p[P_GEAR_EFF])
        else:
            torque = f_trac * p[P_WHEEL_RADIUS] * p[P_GEAR_EFF] / ratios[gear]
        e_mech = torque * omega * dt
        eta_m = machine_efficiency(omega, torque, p, map_speed, map_torque, map_eff)
        e_elec = e_mech / eta_m if e_mech >= 0.0 else e_mech * eta_m
        e_inv = e_elec / p[P_INV_EFF] if e_elec >= 0.0 else e_elec * p[P_INV_EFF]
        aux, at_load = _interp_cursor(t + 0.5 * dt, load_time, aux_w, at_load)
        epto, at_load = _interp_cursor(t + 0.5 * dt, load_time, epto_w, at_load)
        obc, at_load = _interp_cursor(t + 0.5 * dt, load_time, obc_w, at_load)
        p_dc = e_inv / dt + aux + epto - obc
        current = battery_current_a(p_dc, p)

        out[C_TIME, n], out[C_DIST, n], out[C_SPEED, n], out[C_TARGET, n] = t, s, v, target
        out[C_ACCEL, n], out[C_STATE, n], out[C_GEAR, n], out[C_GRADIENT, n] = a, state, gear, grad
        out[C_F_TRAC, n], out[C_F_FRIC, n], out[C_F_ROLL, n] = f_trac, f_fric, f_roll
        out[C_F_CLIMB, n], out[C_F_AERO, n] = f_climb, f_aero
        out[C_M_SPEED, n], out[C_M_TORQUE, n], out[C_LIMITED, n], out[C_SOC, n] = omega, torque, limited, soc
        out[C_CURRENT, n], out[C_P_BATT, n], out[C_DS, n] = current, p_dc, ds
        out[C_E_TRAC, n], out[C_E_FRIC, n] = e_wheel, -f_fric * ds
        out[C_E_GEAR_LOSS, n], out[C_E_MACHINE_LOSS, n] = e_mech - e_wheel, e_elec - e_mech
        out[C_E_INV_LOSS, n], out[C_E_BATT_LOSS, n] = e_inv - e_elec, current * current * p[P_RESISTANCE] * dt
        out[C_E_BATT, n] = p[P_OCV] * current * dt
        out[C_E_AUX, n], out[C_E_EPTO, n], out[C_E_OBC, n] = aux * dt, epto * dt, obc * dt

        soc -= current * dt / p[P_CHARGE_C]
        t += dt
        s += ds
        v = v_new
        n += 1
        if state == STANDSTILL and not time_based:
            timer += 1.0
            if timer >= max(1.0, round(stop_time[next_stop] / dt)):
                next_stop += 1
                state = DRIVE
    return n
