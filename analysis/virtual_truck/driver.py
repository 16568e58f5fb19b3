"""Driver, gearbox and engine of the virtual truck: a fixed-step forward simulation (numba kernel).

Each step k holds the state (s_k, v_k) and the acceleration a_k applied until the next step, with
the wheel force F_k that equation (1) needs: (m + 0) a_k = F_k - F_roll - F_climb - F_aero (eqs 1-4).
The force comes from the engine through the engaged gear, F = eta i T / r_dyn, plus the service brake
when the engine's drag is not enough; while a gear shift is in progress the engine is decoupled
(traction interruption, F = brake only). The driver follows the look-ahead target speed (P control
with feed-forward), brakes at a constant rate to each stop, stands for the stop time, and payload
changes only while standing. ``simulate_kernel.py_func`` is the plain-Python reference.

The accessories (air compressor, cooling fan) and the driveline's own losses (gear efficiency,
spin loss) sit between the engine and the gearbox: where the engine burns fuel it makes their
torque on top of what the wheels get, so its full-load torque left for the wheels is less by
them; in a fuel cut its net torque is its friction and the wheels drive them, so the engine's
drag felt at the wheels is friction plus accessories plus spin loss.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..road_load import AIR_DENSITY_KGPM3, G_MPS2

OUTPUTS = ("distance_m", "speed_mps", "accel_mps2", "gradient_pct", "mass_kg", "gear", "engine_speed_rpm",
           "engine_torque_nm", "driver_demand_torque_nm", "full_load_torque_nm", "wheel_force_n",
           "brake_active", "shifting", "clutch_slip", "stop", "fuel_cut")

FAN_RATED_RPM = 1800.0
"""The cooling fan takes its rated power at this engine speed, and P ~ n^3 (fan law)."""


@numba.njit(cache=True)
def full_load_torque_nm(speed_rpm, reference_nm, idle_rpm, max_rpm, max_power_w):
    """Full-load torque [Nm]: 60 % of the reference at idle rising to 100 % at 1000 rpm, limited by
    the rated power, zero above the governed maximum speed."""
    if speed_rpm > max_rpm:
        return 0.0
    rise = min(max((speed_rpm - idle_rpm) / max(1000.0 - idle_rpm, 1.0), 0.0), 1.0)
    torque = reference_nm * (0.6 + 0.4 * rise)
    return min(torque, max_power_w / (2.0 * math.pi * max(speed_rpm, idle_rpm) / 60.0))


@numba.njit(cache=True)
def drag_torque_nm(speed_rpm, reference_nm, idle_rpm, max_rpm):
    """Motoring (fuel cut) torque of the engine [Nm], negative."""
    rise = min(max((speed_rpm - idle_rpm) / (max_rpm - idle_rpm), 0.0), 1.0)
    return -(0.03 + 0.05 * rise) * reference_nm


def friction_torque_nm(engine_speed_rpm: np.ndarray, vehicle) -> np.ndarray:
    """The engine's friction [Nm, positive] at each speed: its motoring torque in a fuel cut."""
    engine, ref = vehicle.engine, vehicle.engine_reference_torque_nm
    return -np.array([drag_torque_nm(r, ref, engine.idle_speed_rpm, engine.max_speed_rpm) for r in engine_speed_rpm],
                     dtype=float)


@numba.njit(cache=True)
def gearbox_torque_nm(engine_side_nm, nominal_over_gear_efficiency):
    """The torque the kernel puts through the gearbox (F = eta_nominal i T / r) for an
    ``engine_side_nm`` that reaches the gearbox input through this gear's efficiency: driving, the
    gear's losses take their share (T = x eta_gear / eta); motored, they pass the other way."""
    if engine_side_nm >= 0.0:
        return engine_side_nm / nominal_over_gear_efficiency
    return engine_side_nm * nominal_over_gear_efficiency


@numba.njit(cache=True)
def _accessory_torque_nm(k, compressor_w, fan_rated_w, speed_rpm):
    """Accessories' torque [Nm] at step k (none after the schedule ends)."""
    if k >= len(compressor_w):
        return 0.0
    power_w = compressor_w[k] + fan_rated_w[k] * (speed_rpm / FAN_RATED_RPM) ** 3
    return power_w / (max(speed_rpm, 1.0) * math.pi / 30.0)


@numba.njit(cache=True)
def _best_gear(speed_mps, ratios, wheel_radius_m, target_rpm):
    """Highest gear whose engine speed is at least ``target_rpm`` (1-based; 1 if none)."""
    best = 1
    for g in range(len(ratios)):
        if speed_mps / wheel_radius_m * ratios[g] * 30.0 / math.pi >= target_rpm:
            best = g + 1
    return best


@numba.njit(cache=True)
def _sync_rpm(speed_mps, ratio, wheel_radius_m):
    return speed_mps / wheel_radius_m * ratio * 30.0 / math.pi


@numba.njit(cache=True)
def simulate_kernel(dt_s, max_steps, allowed_speed_mps, gradient_pct, head_wind_mps, stop_distance_m, stop_duration_s,
                    mass_after_stop_kg, initial_stop_s, initial_mass_kg, vehicle_params, engine_params,
                    ratios, driver_params, compressor_w, fan_rated_w, gear_efficiency, spin_loss_nm, out):
    """Run the drive on a 1 m grid of allowed speed [m/s], gradient [%] and head wind [m/s] (the
    wind's component against the direction of travel: air speed = v + head wind); fill ``out``
    (len(OUTPUTS) x max_steps) and return the number of steps, or -1 if ``max_steps`` was too small.

    vehicle_params = (c_r, c_d, A [m^2], r_dyn [m], eta_dl); engine_params = (reference torque [Nm],
    idle [rpm], max [rpm], max power [W], shift up [rpm], shift down [rpm], shift time [s]);
    ratios = overall ratio per gear; driver_params = (max accel, comfort decel, max decel [m/s^2],
    speed gain [1/s], downhill overspeed [m/s]: on the engine's drag alone the truck may run this
    much above the target before the brakes come on); mass_after_stop_kg[j] = total mass [kg] from the middle of stop j's dwell on.
    compressor_w[k], fan_rated_w[k]: the accessories' schedule per step [W] (none beyond its end);
    gear_efficiency[g]: the driveline's efficiency in gear g + 1 and spin_loss_nm its
    load-independent loss at the gearbox input (eta_dl and 0 for a driveline as nominal).
    """
    c_r, c_d, area, radius, eta = vehicle_params[0], vehicle_params[1], vehicle_params[2], vehicle_params[3], vehicle_params[4]
    t_ref, idle, n_max, p_max = engine_params[0], engine_params[1], engine_params[2], engine_params[3]
    n_up, n_down, shift_time = engine_params[4], engine_params[5], engine_params[6]
    a_max, b_comfort, b_max, gain = driver_params[0], driver_params[1], driver_params[2], driver_params[3]
    overspeed = driver_params[4]
    n_mid = 0.5 * (n_up + n_down)
    last = len(allowed_speed_mps) - 1
    top = len(ratios)
    n_stops = len(stop_distance_m)

    s, v, mass = 0.0, 0.0, initial_mass_kg
    gear, target_gear, shift_left = 0, 0, 0.0
    stop_index, dwell, standing, loaded = 0, initial_stop_s, True, True
    engine_rpm = idle
    for k in range(max_steps):
        i = min(int(s), last - 1)
        frac = min(s - i, 1.0)
        grad = gradient_pct[i] + frac * (gradient_pct[i + 1] - gradient_pct[i])
        alpha = math.atan(grad / 100.0)
        air = v + head_wind_mps[i] + frac * (head_wind_mps[i + 1] - head_wind_mps[i])
        resistance = (mass * G_MPS2 * (c_r * math.cos(alpha) + math.sin(alpha))
                      + 0.5 * AIR_DENSITY_KGPM3 * c_d * area * air * abs(air))
        torque, demand, brake, slip, shifting, gear_out, fuel_cut = 0.0, 0.0, False, False, False, 0, False
        full = full_load_torque_nm(idle, t_ref, idle, n_max, p_max)
        arrive, finished = False, False
        if standing:
            accel, force, brake, engine_rpm = 0.0, resistance, True, idle
            dwell -= dt_s
            if not loaded and stop_index >= 1 and dwell <= 0.5 * stop_duration_s[stop_index - 1]:
                mass, loaded = mass_after_stop_kg[stop_index - 1], True
                resistance = mass * G_MPS2 * (c_r * math.cos(alpha) + math.sin(alpha))
                force = resistance
            if dwell <= 1e-9:
                if stop_index >= n_stops:
                    finished = True
                else:
                    standing, gear = False, 1
        else:
            allowed = allowed_speed_mps[i] + frac * (allowed_speed_mps[i + 1] - allowed_speed_mps[i])
            slope = allowed_speed_mps[i + 1] - allowed_speed_mps[i]
            accel_des = min(max(v * slope + gain * (allowed - v), -b_max), a_max)
            to_stop = stop_distance_m[stop_index] - s
            stopping = to_stop > 0.0 and v > 0.0 and v * v / (2.0 * to_stop) >= 0.9 * b_comfort
            if stopping:
                accel_des = min(accel_des, -min(v * v / (2.0 * to_stop), b_max))
            let_roll = not stopping and slope >= 0.0 and v < allowed + overspeed
            force_des = mass * accel_des + resistance

            if shift_left <= 0.0:
                sync = _sync_rpm(v, ratios[gear - 1], radius)
                rpm = max(sync, idle)
                left = (full_load_torque_nm(rpm, t_ref, idle, n_max, p_max)
                        - _accessory_torque_nm(k, compressor_w, fan_rated_w, rpm) - spin_loss_nm)
                full_force = eta * ratios[gear - 1] * gearbox_torque_nm(left, eta / gear_efficiency[gear - 1]) / radius
                wanted = gear
                if sync > n_up and gear < top:
                    candidate = max(_best_gear(v, ratios, radius, n_mid), gear + 1)
                    new_sync = _sync_rpm(v, ratios[candidate - 1], radius)
                    left = (full_load_torque_nm(new_sync, t_ref, idle, n_max, p_max)
                            - _accessory_torque_nm(k, compressor_w, fan_rated_w, new_sync) - spin_loss_nm)
                    new_force = (eta * ratios[candidate - 1] * gearbox_torque_nm(left, eta / gear_efficiency[candidate - 1])
                                 / radius)
                    if new_force > resistance + 0.05 * mass or sync > n_max - 50.0:
                        wanted = candidate
                elif sync < n_down and gear > 1:
                    wanted = min(_best_gear(v, ratios, radius, n_mid), gear - 1)
                elif (gear > 1 and v > 3.0 and force_des > full_force and full_force < resistance
                      and _sync_rpm(v, ratios[gear - 2], radius) < n_up - 100.0):
                    wanted = gear - 1
                if wanted != gear:
                    target_gear, shift_left = wanted, shift_time
            if shift_left > 0.0:
                shifting = True
                target_rpm = max(_sync_rpm(v, ratios[target_gear - 1], radius), idle)
                engine_rpm += (target_rpm - engine_rpm) * min(dt_s / shift_left, 1.0)
                shift_left -= dt_s
                if shift_left <= 1e-9:
                    shift_left, gear = 0.0, target_gear
                force = min(force_des, 0.0)
                brake = force < 0.0
            else:
                gear_out = gear
                ratio = ratios[gear - 1]
                sync = _sync_rpm(v, ratio, radius)
                slip = sync < idle
                engine_rpm = max(sync, idle)
                full = full_load_torque_nm(engine_rpm, t_ref, idle, n_max, p_max)
                drag = drag_torque_nm(engine_rpm, t_ref, idle, n_max)
                between = _accessory_torque_nm(k, compressor_w, fan_rated_w, engine_rpm) + spin_loss_nm
                nominal_over_gear = eta / gear_efficiency[gear - 1]
                lowest = gearbox_torque_nm(drag - between, nominal_over_gear)
                highest = gearbox_torque_nm(full - between, nominal_over_gear)
                wanted_torque = force_des * radius / (eta * ratio)
                torque = min(max(wanted_torque, lowest), highest)
                fuel_cut = wanted_torque <= lowest
                demand = min(max(wanted_torque, 0.0), full)
                force = eta * ratio * torque / radius
                if force_des < force and not let_roll:
                    force, brake = force_des, True
            accel = (force - resistance) / mass
            to_stop = stop_distance_m[stop_index] - s
            if to_stop <= v * dt_s or (to_stop < 1.0 and v < 1e-3):
                arrive = True
            if arrive or v + accel * dt_s < 0.0:
                accel = -v / dt_s
                force, brake = mass * accel + resistance, True
                if not shifting:
                    torque = min(torque, 0.0)
        out[0, k] = s
        out[1, k] = v
        out[2, k] = accel
        out[3, k] = grad
        out[4, k] = mass
        out[5, k] = gear_out
        out[6, k] = engine_rpm
        out[7, k] = torque
        out[8, k] = demand
        out[9, k] = full
        out[10, k] = force
        out[11, k] = 1.0 if brake else 0.0
        out[12, k] = 1.0 if shifting else 0.0
        out[13, k] = 1.0 if slip else 0.0
        out[14, k] = 1.0 if v == 0.0 and accel == 0.0 else 0.0
        out[15, k] = 1.0 if fuel_cut else 0.0
        if finished:
            return k + 1
        s += v * dt_s + 0.5 * accel * dt_s * dt_s
        v += accel * dt_s
        if arrive:
            v, standing, dwell, loaded = 0.0, True, stop_duration_s[stop_index], False
            stop_index += 1
    return -1
