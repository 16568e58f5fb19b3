"""The virtual truck's driver/gearbox/engine kernel (numba) vs its plain-Python reference, and the
time to generate the demo's inputs (drive, SRTM tiles, MCAP log)."""

import tempfile
import time
from pathlib import Path

from haulprofile.analysis.virtual_truck import drive, load_scenario, write_dem, write_mcap
from haulprofile.analysis.virtual_truck.driver import simulate_kernel
from haulprofile.analysis.virtual_truck.world import build_road
from haulprofile.analysis.virtual_truck.truck import scenario_vehicle, simulate
from bench import result


def bench_virtual_truck_kernel(quick: bool):
    scenario = load_scenario("regional-tunnel")
    vehicle, road = scenario_vehicle(scenario), build_road(scenario, 0)
    simulate(scenario, vehicle, road)  # compile
    t0 = time.perf_counter()
    states = simulate(scenario, vehicle, road)
    ours = time.perf_counter() - t0
    steps = len(states)
    if quick:
        road.stop_distance_m = road.stop_distance_m[:1]
        road.stop_duration_s = road.stop_duration_s[:1]
    t0 = time.perf_counter()
    reference = simulate(scenario, vehicle, road, kernel=simulate_kernel.py_func)
    peer = (time.perf_counter() - t0) * steps / len(reference)
    return [result("virtual_truck_kernel", ours / steps * 1e9, "ns/step (100 Hz)", "same kernel in plain Python",
                   peer / steps * 1e9, steps=steps)]


def bench_virtual_truck_inputs(quick: bool):
    scenario = load_scenario("regional-tunnel")
    with tempfile.TemporaryDirectory() as directory:
        t0 = time.perf_counter()
        virtual = drive(scenario, seed=0)
        t1 = time.perf_counter()
        write_dem(virtual, Path(directory) / "dem")
        t2 = time.perf_counter()
        log = write_mcap(virtual, Path(directory) / "log.mcap")
        t3 = time.perf_counter()
        size = log.stat().st_size
    return [result("virtual_truck_drive_regional", t1 - t0, "s", None, None, minutes=virtual.duration_s / 60),
            result("virtual_truck_write_dem_regional", t2 - t1, "s", None, None),
            result("virtual_truck_write_mcap_regional", t3 - t2, "s", None, None, megabytes=size / 1e6)]


BENCHMARKS = [bench_virtual_truck_kernel, bench_virtual_truck_inputs]
