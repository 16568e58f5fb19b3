"""The shared vehicle model over arrays vs the same equations evaluated per sample in Python."""

import math
import time

import numpy as np

from haulprofile.analysis import road_load
from haulprofile.analysis.vehicle import load_vehicle
from bench import result


def bench_road_load(quick: bool):
    vehicle = load_vehicle("rigid-18t")
    n = 100_000 if quick else 2_000_000
    rng = np.random.default_rng(0)
    speed, accel = rng.uniform(0, 25, n), rng.normal(0, 0.5, n)
    grad, mass = rng.normal(0, 3, n), np.full(n, 20_000.0)
    t0 = time.perf_counter()
    force = road_load.wheel_force_n(speed, accel, grad, mass, vehicle)
    ours = time.perf_counter() - t0
    m = min(n, 100_000)
    t0 = time.perf_counter()
    for k in range(m):
        alpha = math.atan(grad[k] / 100)
        f = (mass[k] * accel[k] + mass[k] * 9.81 * (vehicle.rolling_resistance_coefficient * math.cos(alpha)
             + math.sin(alpha)) + 0.6 * vehicle.drag_coefficient * vehicle.frontal_area_m2 * speed[k] ** 2)
    peer = (time.perf_counter() - t0) * n / m
    assert abs(f - force[m - 1]) < 1e-6 * abs(f) + 1e-6
    return [result("road_load_wheel_force", ours / n * 1e9, "ns/sample", "python per-sample loop",
                   peer / n * 1e9)]


BENCHMARKS = [bench_road_load]
