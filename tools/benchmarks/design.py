"""``analyze design``'s search speed: candidates simulated per second in a full design (NSGA-II,
80 x 70 = 5600 candidates, batched numba kernel on every core) on a 30 min cycle, against the
same candidates simulated one by one with FASTSim 3 (``SimDrive.run`` in a Python loop, the way
T3CO's optimisation loop calls FASTSim). T3CO itself (``pip install t3co``, 2.0.0) pins numpy
1.26, which this project's numpy 2 excludes, so the peer is FASTSim 3 in a loop, said plainly."""

import importlib.util
import time
from pathlib import Path

import numba
import numpy as np
import pandas as pd

from haulprofile.analysis.design import DesignOptions, design_concepts
from haulprofile.analysis.design import components as C
from haulprofile.analysis.design.synthesis import driven
from haulprofile.analysis.simulate import distance_cycle
from haulprofile.analysis.vecto import read_vdri
from haulprofile.analysis.vehicle import load_vehicle
from bench import result

TEST_DATA = Path(__file__).resolve().parents[2] / "tests" / "data"


def _simulate_bench():
    spec = importlib.util.spec_from_file_location("haulprofile_bench_simulate_peer", Path(__file__).parent / "simulate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def thirty_minute_cycle(vehicle, minutes: float = 30.0):
    """VECTO LongHaul cut where the driver model reaches ``minutes`` of driving."""
    frame = read_vdri(TEST_DATA / "vecto-cycles" / "LongHaul.vdri")
    mass = vehicle.curb_mass_kg + 0.5 * vehicle.max_payload_kg
    whole = distance_cycle(frame, mass, "LongHaul")
    trace = driven(whole, vehicle, 1.0)
    end_m = float(np.interp(minutes * 60.0, trace["time_s"], np.cumsum(trace["speed_mps"])))
    cut = frame[frame["distance_m"] <= end_m].copy()
    cut.loc[cut.index[-1], ["target_speed_mps", "stop_time_s"]] = [0.0, 2.0]
    return distance_cycle(cut, mass, f"LongHaul first {end_m / 1000:.0f} km ({minutes:g} min)")


def _fastsim_loop(fastsim, vehicle, cycle, candidates, sizing, mass_delta_kg):
    """Each candidate as a FASTSim BEV (our road load, its power, battery and mass) on the cycle as driven."""
    trace = driven(cycle, vehicle, 1.0)
    base = _simulate_bench()
    fs_cycle = fastsim.Cycle.from_dict({**fastsim.Cycle.from_resource("udds.csv").to_dict(),
                                        "time_seconds": trace["time_s"].tolist(),
                                        "speed_meters_per_second": trace["speed_mps"].tolist(),
                                        "grade": (np.arctan(trace["gradient_pct"] / 100.0)).tolist(),
                                        "dist_meters": [], "elev_meters": [], "pwr_max_chrg_watts": [],
                                        "temp_amb_air_kelvin": [], "pwr_solar_load_watts": []})
    template = base.fastsim_vehicle(fastsim, vehicle).to_dict()
    params = {**fastsim.SimDrive(fastsim.Vehicle.from_dict(template), fs_cycle).to_dict()["sim_params"],
              "trace_miss_opts": "Allow"}  # a small candidate falls behind the trace instead of stopping
    cycle_dict = fs_cycle.to_dict()
    energies = []
    started = time.perf_counter()
    for i in range(len(candidates)):
        d = {**template}
        d["mass_kilograms"] = float(trace["mass_kg"].mean() + mass_delta_kg[i])
        d["pt_type"]["BEV"]["em"]["pwr_out_max_watts"] = float(sizing.peak_power_w[i])
        d["pt_type"]["BEV"]["res"]["energy_capacity_joules"] = float(candidates.battery_energy_j[i])
        d["pt_type"]["BEV"]["res"]["pwr_out_max_watts"] = float(sizing.battery_peak_power_w[i])
        sd = fastsim.SimDrive.from_dict({"veh": d, "cyc": cycle_dict, "sim_params": params})
        sd.run()
        energies.append(sd.to_dict()["veh"]["state"])
    return time.perf_counter() - started


def bench_design(quick: bool):
    try:
        import fastsim
    except ImportError as exc:
        print(f"design vs FASTSim skipped: fastsim is not installed ({exc})")
        return []
    vehicle = load_vehicle("tractor-40t")
    cycle = thirty_minute_cycle(vehicle, 10.0 if quick else 30.0)
    options = DesignOptions(population=24 if quick else 80, generations=4 if quick else 70, daily_distance_m=400e3)
    design_concepts([cycle], vehicle, DesignOptions(population=8, generations=1))  # compile the kernels once
    design = design_concepts([cycle], vehicle, options)
    ours = design.summary()
    peer_n = 10 if quick else 40
    x = design.outcome.x[np.linspace(0, len(design.outcome.x) - 1, peer_n).astype(int)]
    c = design.evaluator.decode(x)
    s = C.size(c, design.evaluator.voltage_v, design.evaluator.resistance)
    peer_s = _fastsim_loop(fastsim, vehicle, cycle, c, s, design.evaluator.mass_delta_kg(s))
    peer_rate = peer_n / peer_s
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    t0 = time.perf_counter()
    design.evaluator.evaluate(x)
    single = peer_n / (time.perf_counter() - t0)
    numba.set_num_threads(threads)
    rate = ours["candidates"] / ours["search_s"]
    return [
        result("design_candidates_per_s", rate, "candidates/s (ratio = ours/peer, >1: ours faster)",
               "FASTSim 3 SimDrive.run per candidate in a Python loop (T3CO cannot be installed with numpy 2)",
               peer_rate, ratio=rate / peer_rate, cycle=cycle.name, candidates=ours["candidates"],
               design_s=ours["search_s"], threads=threads),
        result("design_candidates_per_s_one_thread", single, "candidates/s, kernel alone on one thread",
               "FASTSim 3 loop", peer_rate, ratio=single / peer_rate, candidates=peer_n),
    ]


BENCHMARKS = [bench_design]
