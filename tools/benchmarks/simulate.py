"""Longitudinal simulation vs FASTSim 3 on the same road load and the same 1-hour speed trace,
and the closing note's energy per km of the example vehicles on VECTO and virtual-truck cycles."""

import dataclasses
import time
from pathlib import Path

import numpy as np
import pandas as pd

from haulprofile.analysis.simulate import DriverSettings, read_cycle, simulate_cycle, time_cycle
from haulprofile.analysis.vehicle import load_vehicle
from bench import result

TEST_DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
MASS_KG = 18_000.0


def _best_of(repeats: int, run) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        times.append(time.perf_counter() - t0)
    return min(times)


def _fastsim_trace(fastsim, hours: float) -> dict:
    """FASTSim's shipped UDDS and HWFET traces back to back until ``hours`` are filled."""
    pieces, t_end = [], 0.0
    while t_end < hours * 3600.0:
        for name in ("udds.csv", "hwfet.csv"):
            d = fastsim.Cycle.from_resource(name).to_dict()
            t, v = np.asarray(d["time_seconds"], float), np.asarray(d["speed_meters_per_second"], float)
            pieces.append((t + t_end + (1.0 if pieces else 0.0), v))
            t_end = pieces[-1][0][-1]
    time_s = np.concatenate([p[0] for p in pieces])
    keep = time_s <= max(hours * 3600.0, 1.0) + 1e-9
    return {"time_seconds": time_s[keep].tolist(),
            "speed_meters_per_second": np.concatenate([p[1] for p in pieces])[keep].tolist()}


def fastsim_vehicle(fastsim, vehicle):
    """A FASTSim BEV with our road load (mass, c_d, A, c_r, r_dyn; no wheel inertia) and a
    powertrain large enough to follow the trace, as ours is in this comparison."""
    d = fastsim.Vehicle.from_resource("2022_Renault_Zoe_ZE50_R135.yaml").to_dict()
    d["mass_kilograms"] = MASS_KG
    d["chassis"].update(drag_coef=vehicle.drag_coefficient, frontal_area_square_meters=vehicle.frontal_area_m2,
                        wheel_rr_coef=vehicle.rolling_resistance_coefficient,
                        wheel_inertia_kilogram_square_meters=0.0, wheel_radius_meters=vehicle.wheel_radius_m)
    d["pt_type"]["BEV"]["em"]["pwr_out_max_watts"] = 2e6
    d["pt_type"]["BEV"]["res"]["pwr_out_max_watts"] = 1e7
    d["pt_type"]["BEV"]["res"]["energy_capacity_joules"] = 3.6e10
    veh = fastsim.Vehicle.from_dict(d)
    veh.set_save_interval(1)
    return veh


def bench_simulate_vs_fastsim(quick: bool):
    try:
        import fastsim
    except ImportError as exc:
        print(f"simulate vs FASTSim skipped: fastsim is not installed ({exc})")
        return []
    hours = 0.25 if quick else 1.0
    rigid = load_vehicle("rigid-18t")
    ep = dataclasses.replace(rigid.electric_powertrain, rotating_mass_kg=0.0, machine_max_power_w=2e6,
                             machine_max_torque_nm=50_000.0, max_recuperation_power_w=2e6)
    ours_vehicle = dataclasses.replace(rigid, electric_powertrain=ep)
    trace = _fastsim_trace(fastsim, hours)
    cycle = time_cycle(pd.DataFrame({"time_s": trace["time_seconds"], "speed_mps": trace["speed_meters_per_second"]}),
                       MASS_KG, "FASTSim UDDS+HWFET")
    fs_vehicle = fastsim_vehicle(fastsim, rigid)
    fs_cycle = fastsim.Cycle.from_dict({**fastsim.Cycle.from_resource("udds.csv").to_dict(), **trace,
                                        "grade": [0.0] * len(trace["time_seconds"]),
                                        "dist_meters": [], "elev_meters": [], "pwr_max_chrg_watts": [],
                                        "temp_amb_air_kelvin": [], "pwr_solar_load_watts": []})
    holder = {}

    def run_fastsim():
        sd = fastsim.SimDrive(fs_vehicle, fs_cycle)
        sd.run()
        holder["fs"] = sd

    lines = []
    simulate_cycle(cycle, ours_vehicle)
    repeats = 3 if quick else 5
    t_fastsim = _best_of(repeats, run_fastsim)
    history = holder["fs"].to_dict()["veh"]["history"]
    fs_power = np.asarray(history["pwr_tractive_watts"])
    fs_time = np.asarray(history["time_seconds"])
    fs_positive_kwh = float(np.sum(np.clip(fs_power, 0, None)[1:] * np.diff(fs_time))) / 3.6e6
    for dt in (1.0, 0.1):
        settings = DriverSettings(time_step_s=dt)
        holder["ours"] = simulate_cycle(cycle, ours_vehicle, settings=settings)
        t_ours = _best_of(repeats, lambda: simulate_cycle(cycle, ours_vehicle, settings=settings))
        ours_kwh = holder["ours"].numbers["wheel_positive_energy_kwh"]
        lines.append(result(f"simulate_{hours:g}h_trace_dt{dt:g}s_run_time", t_ours, "s (ratio>1: ours faster)",
                            "FASTSim 3 SimDrive.run (1 s steps)", t_fastsim))
        lines.append(result(f"simulate_{hours:g}h_trace_dt{dt:g}s_positive_wheel_energy", ours_kwh,
                            "kWh (ratio = FASTSim/ours)", "FASTSim 3 pwr_tractive_watts > 0", fs_positive_kwh))
    return lines


def bench_energy_per_km(quick: bool):
    """Closing note: battery and wheel kWh/km of the example vehicles (half payload on VECTO
    cycles, the scenario's own mass on virtual-truck drives)."""
    lines = []
    vecto = TEST_DATA / "vecto-cycles"
    names = ["RegionalDelivery"] if quick else ["RegionalDelivery", "LongHaul"]
    for vehicle_name in ("rigid-18t", "tractor-40t"):
        vehicle = load_vehicle(vehicle_name)
        cycles = [read_cycle(vecto / f"{n}.vdri", vehicle) for n in names if (vecto / f"{n}.vdri").is_file()]
        cycles += _virtual_truck_cycles(vehicle, quick)
        for cycle in cycles:
            s = simulate_cycle(cycle, vehicle).numbers
            lines.append(result(f"energy_per_km_{vehicle_name}_{cycle.name}", s["battery_kwh_per_km"],
                                "kWh/km at the battery", None, None,
                                wheel_positive_kwh_per_km=s["wheel_positive_kwh_per_km"],
                                distance_km=s["distance_km"], mean_mass_kg=s["mean_mass_kg"],
                                missed_target_s=s["missed_target_s"]))
    return lines


def _virtual_truck_cycles(vehicle, quick: bool) -> list:
    """Each scenario driven by its own vehicle (speed, gradient, payload over time); another vehicle
    carries the same payload, clipped to its own maximum payload."""
    try:
        from haulprofile.analysis.virtual_truck import SCENARIOS, drive, load_scenario, scenario_vehicle
    except ImportError as exc:
        print(f"virtual-truck scenarios skipped: {exc}")
        return []
    cycles = []
    for name in list(SCENARIOS)[: 1 if quick else None]:
        scenario = load_scenario(name)
        own = scenario_vehicle(scenario)
        truth = drive(scenario, own, seed=0).truth[["time_s", "speed_mps", "gradient_pct", "mass_kg"]].copy()
        payload = truth["mass_kg"] - own.curb_mass_kg
        truth["mass_kg"] = vehicle.curb_mass_kg + payload.clip(0.0, vehicle.max_payload_kg or np.inf)
        cycles.append(time_cycle(truth, vehicle.curb_mass_kg, f"virtual-{name}"))
    return cycles


BENCHMARKS = [bench_simulate_vs_fastsim, bench_energy_per_km]
