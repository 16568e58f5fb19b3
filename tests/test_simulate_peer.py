"""Peer check against FASTSim 3 (optional: skipped when fastsim is not installed)."""

import dataclasses
import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.simulate import simulate_cycle, time_cycle
from haulprofile.analysis.vehicle import load_vehicle


def test_positive_wheel_energy_agrees_with_fastsim_on_udds(monkeypatch):
    fastsim = pytest.importorskip("fastsim", reason="FASTSim 3 is an optional peer (pip install fastsim)")
    tools = Path(__file__).resolve().parents[1] / "tools"
    monkeypatch.syspath_prepend(str(tools))
    spec = importlib.util.spec_from_file_location("haulprofile_bench_simulate", tools / "benchmarks" / "simulate.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    MASS_KG, fastsim_vehicle = bench.MASS_KG, bench.fastsim_vehicle

    rigid = load_vehicle("rigid-18t")
    ep = dataclasses.replace(rigid.electric_powertrain, rotating_mass_kg=0.0, machine_max_power_w=2e6,
                             machine_max_torque_nm=50_000.0, max_recuperation_power_w=2e6)
    udds = fastsim.Cycle.from_resource("udds.csv")
    sd = fastsim.SimDrive(fastsim_vehicle(fastsim, rigid), udds)
    sd.run()
    history = sd.to_dict()["veh"]["history"]
    power, time = np.asarray(history["pwr_tractive_watts"]), np.asarray(history["time_seconds"])
    fastsim_kwh = np.sum(np.clip(power, 0, None)[1:] * np.diff(time)) / 3.6e6
    trace = udds.to_dict()
    cycle = time_cycle(pd.DataFrame({"time_s": trace["time_seconds"], "speed_mps": trace["speed_meters_per_second"],
                                     "gradient_pct": 100 * np.asarray(trace["grade"])}), MASS_KG)
    ours = simulate_cycle(cycle, dataclasses.replace(rigid, electric_powertrain=ep))
    assert ours.numbers["missed_target_intervals"] == 0
    assert ours.numbers["wheel_positive_energy_kwh"] == pytest.approx(fastsim_kwh, rel=0.01)
