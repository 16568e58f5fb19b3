"""Synthetic drives with the structure of real truck data, for tests and benchmarks.

Trips between stops: a driver accelerates (less uphill and when heavy), cruises around a target
speed with slow fluctuations, and brakes to stop at the trip's end; the road gradient is a smooth
function of the position on a loop road (so it cannot change at standstill); at some stops the
payload changes (pick-ups and deliveries), so mass changes only at standstill. A drive starts
parked at the depot and, once ``duration_s`` is reached, returns there and parks (so it lasts a
little longer than asked).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

G = 9.81
KINDS = {
    # cruise speed [km/h], trip length [m], stop [s] (ranges), gradient amplitude [%], loop length [m]
    "urban": ((30.0, 50.0), (300.0, 2000.0), (10.0, 120.0), 1.5, 6000.0),
    "regional": ((50.0, 80.0), (2000.0, 12000.0), (20.0, 300.0), 2.5, 30000.0),
    "long-haul": ((78.0, 85.0), (20000.0, 80000.0), (60.0, 900.0), 2.0, 60000.0),
}


def synthetic_drive(duration_s: float, seed: int = 0, kind: str = "regional", rate_hz: float = 1.0,
                    mass_range_kg: tuple[float, float] = (12_000.0, 18_000.0),
                    payload_change_probability: float = 0.5) -> pd.DataFrame:
    """A drive of ``duration_s`` [s] sampled at ``rate_hz`` [Hz]: ``time_s``, ``speed_mps``,
    ``gradient_pct``, ``mass_kg``, ``distance_m``."""
    (v_low, v_high), (l_low, l_high), (stop_low, stop_high), amplitude, loop_m = KINDS[kind]
    rng = np.random.default_rng(seed)
    wavelengths = loop_m / rng.integers(max(1, int(loop_m / 6000.0)), int(loop_m / 400.0) + 1, 6)
    phases = rng.uniform(0, 2 * np.pi, 6)
    weights = rng.uniform(0.3, 1.0, 6)
    weights *= amplitude / np.sqrt(0.5 * np.sum(weights ** 2))

    def gradient_at(distance):
        return np.sum(weights * np.sin(2 * np.pi * distance / wavelengths + phases))

    dt = 1.0 / rate_hz
    rows = []
    v = s = 0.0
    m = rng.uniform(*mass_range_kg)
    stop_left = rng.uniform(stop_low, stop_high)
    trip_end = rng.uniform(l_low, l_high)
    target = rng.uniform(v_low, v_high) / 3.6
    wobble = 0.0
    going_home = False
    k = 0
    while True:
        time = k * dt
        grad = gradient_at(s)
        rows.append((time, v, grad, m, s))
        k += 1
        if stop_left > 0:
            stop_left -= dt
            if going_home and stop_left <= 0:
                break
            if stop_left <= 0:
                if rng.random() < payload_change_probability:
                    m = round(rng.uniform(*mass_range_kg), -1)
                trip_end = s + rng.uniform(l_low, l_high)
                target = rng.uniform(v_low, v_high) / 3.6
            continue
        if time >= duration_s and not going_home:
            going_home = True
            trip_end = (np.floor((s + v * v / 1.4 + 2 * v) / loop_m) + 1) * loop_m
        wobble = 0.98 * wobble + rng.normal(0.0, 0.12)
        brake = 0.7
        remaining = trip_end - s
        if remaining <= v * v / (2 * brake) + v * dt:
            a = -min(v / dt, max(brake, v * v / (2 * max(remaining, 0.5))))
        else:
            slope = G * grad / 100.0
            a_max = max(0.05, 9000.0 / m - 0.5 * slope - 0.004 * v)
            a = np.clip((target + wobble - v) / 4.0, -0.6, a_max)
        v = max(0.0, v + a * dt)
        s += v * dt
        if v < 0.05 and remaining < 5.0:
            v = 0.0
            if going_home:
                s = trip_end
            stop_left = rng.uniform(stop_low, stop_high) if not going_home else 30.0
    return pd.DataFrame(rows, columns=["time_s", "speed_mps", "gradient_pct", "mass_kg", "distance_m"])
