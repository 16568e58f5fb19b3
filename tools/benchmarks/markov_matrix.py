"""Paper selection against the refined default on many drives: virtual-truck scenarios (ground truth
speed, gradient, mass; three seeds each and their concatenation) and synthetic drives.

``python tools/benchmarks/markov_matrix.py [OUT.json [paper,refined,kinematic]]`` prints one line per drive and
method: score S (15), valid, the load criteria's plain relative deviations and the selection's wall
time. ``refined-no-loads`` is the refined selection without a vehicle (kinematic criteria only).
``paper-fwd-accel`` is the paper's cycle with the forward-difference acceleration column
cycles had before (its loads as the loads stage saw them).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import pandas as pd

from haulprofile.analysis import virtual_truck
from haulprofile.analysis.markov import build_chain, count_transitions, select_cycle
from haulprofile.analysis.markov.converge import select_refined
from haulprofile.analysis.markov.load_criteria import evaluate_loads, load_target, within_allowance
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.testing.drives import synthetic_drive

SCENARIOS = ("urban-delivery", "regional-tunnel", "long-haul")


def drives(seeds=(0, 1, 2)):
    for seed in seeds:
        parts, offset = [], 0.0
        for name in SCENARIOS:
            run = virtual_truck.drive(virtual_truck.load_scenario(name), seed=seed)
            truth = run.truth[["time_s", "speed_mps", "accel_mps2", "gradient_pct", "mass_kg"]].copy()
            yield f"{name}/{seed}", truth, run.vehicle
            part = truth.copy()
            part["time_s"] += offset
            offset = part["time_s"].iloc[-1] + 0.1
            parts.append(part)
        yield f"concatenation/{seed}", pd.concat(parts, ignore_index=True), load_vehicle("rigid-18t")
    for kind, vehicle in (("urban", "rigid-18t"), ("regional", "rigid-18t"), ("long-haul", "tractor-40t")):
        for seed in (0, 1):
            mass = (12_000.0, 18_000.0) if vehicle == "rigid-18t" else (16_000.0, 40_000.0)
            yield (f"synthetic-{kind}/{seed}", synthetic_drive(3 * 3600, seed=100 + seed, kind=kind, mass_range_kg=mass),
                   load_vehicle(vehicle))


def main(out=None, methods=("paper", "refined")):
    rows = []
    for name, frame, vehicle in drives():
        counts = count_transitions(frame)
        chain = build_chain(counts)
        target = load_target(frame, vehicle, chain)
        runs = []
        if "paper" in methods:
            t0 = time.perf_counter()
            paper = select_cycle(counts, 1800, 100_000, seed=0, chain=chain)
            wall = time.perf_counter() - t0
            forward = paper.cycle.assign(accel_mps2=np.append(np.diff(paper.cycle["speed_mps"]), 0.0))
            runs += [("paper", paper, paper.cycle, wall), ("paper-fwd-accel", paper, forward, wall)]
        if "refined" in methods:
            t0 = time.perf_counter()
            refined = select_refined(counts, 1800, 0, chain, target, vehicle)[0]
            runs.append(("refined", refined, refined.cycle, time.perf_counter() - t0))
        if "kinematic" in methods:
            t0 = time.perf_counter()
            kinematic = select_refined(counts, 1800, 0, chain)[0]
            runs.append(("refined-no-loads", kinematic, kinematic.cycle, time.perf_counter() - t0))
        for method, s, cycle, wall in runs:
            loads = evaluate_loads(cycle, vehicle, target)
            row = {"drive": name, "method": method, "score": s.criteria.score, "valid": s.criteria.valid,
                   "wall_s": wall, "loads_ok": within_allowance(loads),
                   "loads": {k: v["relative"] for k, v in loads.items()},
                   "load_deviation": {k: v["deviation"] for k, v in loads.items()}}
            rows.append(row)
            rel = [v["relative"] for v in loads.values()]
            print(f"{name:24s} {method:15s} S {s.criteria.score:.3f} valid {s.criteria.valid!s:5s} "
                  f"{wall:5.2f} s loads_ok {row['loads_ok']!s:5s} E+ {rel[0]:+.3f} E- {rel[1]:+.3f} "
                  f"DET {min(rel[2:8]):+.3f}..{max(rel[2:8]):+.3f} P {rel[8] if rel[8] is not None else float('nan'):+.3f} "
                  f"{rel[9] if rel[9] is not None else float('nan'):+.3f} {rel[10]:+.3f} "
                  f"TVD {loads['speed_torque_residence_distance']['candidate']:.3f}", flush=True)
    if out:
        with open(out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None,
         tuple(sys.argv[2].split(",")) if len(sys.argv) > 2 else ("paper", "refined"))
