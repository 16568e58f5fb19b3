"""Gradient and mass estimation: (1) our RLS kernel against padasip's FilterRLS on the same
regression and forgetting factor (equal estimates, speed ratio); (2) gradient + LS/RLS/LM over a
long drive at 10 Hz: seconds after JIT and peak RSS, measured in a fresh process."""

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from bench import CACHE_DIR, result

FORGETTING_FACTOR = 0.9985
CURB_MASS_KG = 8818.8
INITIAL_COVARIANCE = 1000.0


def mass_regression(n: int, seed: int = 0):
    """phi [m/s²] and y [N] of (10) for a 22 t truck with noise, as the data filter leaves them."""
    rng = np.random.default_rng(seed)
    phi = 0.1 + rng.gamma(2.0, 0.12, n)
    y = 22_007.4 * phi + rng.normal(0, 1500, n)
    return phi, y


def bench_rls_vs_padasip(quick: bool):
    import padasip

    from haulprofile.analysis.mass import kernels

    n = 20_000 if quick else 100_000
    phi, y = mass_regression(n)
    phi2 = phi.reshape(-1, 1)
    kernels.rls(phi2[:10], y[:10], FORGETTING_FACTOR, np.array([CURB_MASS_KG]), np.array([[INITIAL_COVARIANCE]]))
    runs = []
    for _ in range(5):
        t0 = time.perf_counter()
        ours = kernels.rls(phi2, y, FORGETTING_FACTOR, np.array([CURB_MASS_KG]), np.array([[INITIAL_COVARIANCE]]))
        runs.append(time.perf_counter() - t0)
    ours_s = min(runs)
    peer = padasip.filters.FilterRLS(1, mu=FORGETTING_FACTOR, eps=1 / INITIAL_COVARIANCE, w=np.array([CURB_MASS_KG]))
    t0 = time.perf_counter()
    _, _, history = peer.run(y, phi2)
    peer_s = time.perf_counter() - t0
    peer_path = np.append(history[1:, 0], peer.w[0])  # padasip logs weights before each update
    deviation = float(np.max(np.abs(peer_path / ours[:, 0] - 1)))
    assert deviation < 1e-9, deviation
    return [result("rls_kernel_vs_padasip_FilterRLS", ours_s, "s", "padasip FilterRLS", peer_s,
                   samples=n, forgetting_factor=FORGETTING_FACTOR, final_mass_kg=float(ours[-1, 0]),
                   peer_final_mass_kg=float(peer_path[-1]), max_relative_deviation=deviation)]


def long_drive(hours: float, rate_hz: float = 10.0):
    """A synthetic signals table and SRTM tiles for a drive along 47.5 N, cached in .bench-cache."""
    from haulprofile.analysis import road_load
    from haulprofile.analysis.dem.srtm import write_hgt
    from haulprofile.analysis.kinematics import acceleration_mps2, distance_m
    from haulprofile.analysis.vehicle import load_vehicle

    folder = CACHE_DIR / f"estimation-{hours:g}h"
    table = folder / "signals.parquet"
    if table.is_file():
        return table, folder / "dem"
    rng = np.random.default_rng(1)
    vehicle = load_vehicle("rigid-18t")
    time_s = np.arange(0, hours * 3600, 1 / rate_hz)
    target = np.clip(17 + 5 * np.sin(time_s / 90) + 3 * np.sin(time_s / 23 + 1), 0, None)
    target *= np.clip(np.abs(((time_s + 900) % 1800) - 900) / 60 - 0.5, 0, 1)  # a 60 s stop every 30 min
    speed = pd.Series(target).rolling(int(10 * rate_hz), center=True, min_periods=1).mean().to_numpy()
    accel = np.gradient(speed, time_s)
    s = distance_m(time_s, speed)

    def road(x):
        return 500 + 40 * np.sin(x / 1500) + 15 * np.sin(x / 400 + 1) + 4 * np.sin(x / 170)

    gradient = 100 * (road(s + 0.5) - road(s - 0.5))
    force = road_load.wheel_force_n(speed, accel, gradient, 20_000.0, vehicle)
    ratios = np.array(vehicle.total_ratios)
    rpm_per_mps = ratios * 60 / (2 * np.pi * vehicle.wheel_radius_m)
    gear = np.argmax(speed[:, None] * rpm_per_mps[None, :] < 1500, axis=1)
    m_per_deg = np.radians(1) * 6_371_000 * np.cos(np.radians(47.5))
    lon = 6.02 + s / m_per_deg
    folder.mkdir(parents=True, exist_ok=True)
    n_side = 1201
    for tile_lon in range(6, int(np.floor(lon.max())) + 1):
        lons = tile_lon + np.arange(n_side) / (n_side - 1)
        heights = road((lons - 6.02) * m_per_deg) + 1.5 * np.sin((lons - 6.02) * m_per_deg / 230)
        write_hgt(folder / "dem" / f"N47E{tile_lon:03d}.hgt", np.repeat(heights[None, :], n_side, axis=0))
    frame = pd.DataFrame({
        "time_s": time_s, "speed_mps": speed + rng.normal(0, 0.02, len(time_s)),
        "latitude_deg": 47.5 + rng.normal(0, 1.5e-5, len(time_s)), "longitude_deg": lon,
        "gps_h_acc_m": np.full(len(time_s), 2.0), "gps_v_acc_m": np.full(len(time_s), 3.0),
        "pressure_pa": 101325 * (1 - road(s) / 44330.8) ** 5.255 + rng.normal(0, 2, len(time_s)),
        "accel_x_mps2": accel + 9.81 * np.sin(np.arctan(gradient / 100)) + rng.normal(0, 0.2, len(time_s)),
        "engine_speed_rpm": speed * rpm_per_mps[gear],
        "engine_torque_nm": force * vehicle.wheel_radius_m / (vehicle.driveline_efficiency * ratios[gear]),
        "current_gear": gear + 1.0,
    })
    frame["accel_mps2"] = acceleration_mps2(time_s, frame["speed_mps"].to_numpy())
    frame["distance_m"] = distance_m(time_s, frame["speed_mps"].to_numpy())
    frame.to_parquet(table)
    return table, folder / "dem"


CHILD = """
import json, resource, sys, time
import pandas as pd
from haulprofile.analysis.dem import open_dem
from haulprofile.analysis.gradient import estimate_gradient, smoother
from haulprofile.analysis import mass as mass_package
from haulprofile.analysis.mass import estimate_mass
from haulprofile.analysis.vehicle import load_vehicle
frame = pd.read_parquet(sys.argv[1])
dem, vehicle = open_dem(sys.argv[2]), load_vehicle("rigid-18t")
spent = {"smoother": 0.0, "joint": 0.0}
def timed(owner, name, key):
    inner = getattr(owner, name)
    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            spent[key] += time.perf_counter() - t0
    setattr(owner, name, wrapper)
timed(smoother.GradientSmoother, "estimate", "smoother")
timed(mass_package, "_joint", "joint")
def run(part):
    gradient = estimate_gradient(part, dem)
    part = part.assign(**gradient.samples)
    return estimate_mass(part, vehicle)
run(frame.iloc[:20000])  # JIT and tile loading
spent.update(smoother=0.0, joint=0.0)
t0 = time.perf_counter()
mass = run(frame)
seconds = time.perf_counter() - t0
ok = [s["mass_kg"] for s in mass.segments if s["mass_kg"] is not None]
print(json.dumps({"seconds": seconds, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "samples": len(frame), "segments_ok": len(ok), "median_mass_kg": sorted(ok)[len(ok) // 2],
                  "smoother_s": spent["smoother"], "joint_s": spent["joint"],
                  "old_estimator_s": seconds - spent["smoother"] - spent["joint"]}))
"""


def bench_gradient_and_mass_long_drive(quick: bool):
    """Gradient (paper fusion + smoother) and mass (LS/RLS/LM + joint) of a long drive; the old
    estimator (paper fusion, LS/RLS/LM) is the same run without the time spent in the smoother
    and the joint fit, so the ratio says what the new estimation costs."""
    hours = 1.0 if quick else 10.0
    table, dem = long_drive(hours)
    out = subprocess.run([sys.executable, "-c", CHILD, str(table), str(dem)], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[2])
    measured = json.loads(out.stdout.strip().splitlines()[-1])
    extra = {k: v for k, v in measured.items() if k not in ("seconds", "old_estimator_s")}
    return [result(f"estimation_speed_gradient_and_mass_{hours:g}h_at_10Hz", measured["seconds"], "s",
                   "old estimator (paper fusion + LS/RLS/LM) in the same run", measured["old_estimator_s"], **extra),
            result(f"gradient_and_mass_{hours:g}h_at_10Hz_peak_rss", measured["peak_rss_mb"], "MB")]


BENCHMARKS = [bench_rls_vs_padasip, bench_gradient_and_mass_long_drive]


def bench_estimation_accuracy(quick: bool):
    """Gradient RMSE (smoother, paper fusion (8), barometer only, map only) and mass error per
    segment (old LS, joint with the accelerometer, after calibration with one weighing) on the
    shipped virtual-truck scenarios, as they are ('ideal') and in the imperfect world of the tests
    (DEM with 5 m correlated error and a bridge, 1.5 hPa drift, IMU pitch 1.5° + bias, torque gain
    +3 %, c_r of the vehicle file +15 %)."""
    tests = Path(__file__).resolve().parents[2] / "tests"
    sys.path.insert(0, str(tests))
    from imperfect_world import ErroneousDem, Imperfections, imperfect_signals, mismatched_vehicle, on_grid
    from test_gradient_virtual_truck import signals_from_drive

    from haulprofile.analysis import virtual_truck
    from haulprofile.analysis.dem import open_dem
    from haulprofile.analysis.gradient import estimate_gradient
    from haulprofile.analysis.mass import estimate_mass

    lines = []
    for name in ["regional-tunnel"] if quick else ["regional-tunnel", "long-haul", "urban-delivery"]:
        folder = CACHE_DIR / f"accuracy-{name}"
        table = folder / "signals.parquet"
        if not table.is_file():
            drive = virtual_truck.drive(virtual_truck.load_scenario(name), seed=0)
            virtual_truck.write_dem(drive, folder / "dem")
            signals_from_drive(drive).to_parquet(table)
            drive.truth.to_parquet(folder / "truth.parquet")
        signals, truth = pd.read_parquet(table), pd.read_parquet(folder / "truth.parquet")
        dem = open_dem(folder / "dem")
        vehicle = virtual_truck.scenario_vehicle(virtual_truck.load_scenario(name))
        imperfections = Imperfections()
        for world in ("ideal", "imperfect"):
            if world == "imperfect":
                signals, dem = imperfect_signals(signals, imperfections), ErroneousDem(dem, truth, imperfections)
                vehicle = mismatched_vehicle(vehicle, imperfections)
            gradient = estimate_gradient(signals, dem)
            grid = gradient.grid
            s = grid["distance_m"].to_numpy()
            true_gradient = on_grid(grid, truth, "gradient_pct")
            tunnel = on_grid(grid, truth, "in_tunnel") > 0.5
            bridge = (np.abs(s - imperfections.bridge_at_m) < imperfections.bridge_length_m / 2
                      if world == "imperfect" else np.zeros(len(s), bool))
            rmse = {}
            for column in ("gradient_smooth_pct", "gradient_paper_pct", "gradient_baro_pct", "gradient_map_pct"):
                error = grid[column].to_numpy() - true_gradient
                rmse[column] = {where: round(float(np.sqrt(np.nanmean(error[mask] ** 2))), 3)
                                for where, mask in (("outside", ~tunnel & ~bridge), ("tunnel", tunnel),
                                                    ("bridge", bridge)) if mask.any()}
            frame = signals.assign(**gradient.samples)
            mass = estimate_mass(frame, vehicle)
            time_s, true_mass = truth["time_s"].to_numpy(), truth["mass_kg"].to_numpy()
            true = [true_mass[(time_s >= seg["start_s"]) & (time_s <= seg["end_s"])][0] for seg in mass.segments]
            known = next((j for j, seg in enumerate(mass.segments) if seg["mass_kg"] is not None), None)
            calibrated = estimate_mass(frame, vehicle, known_masses={known: float(true[known])}) if known is not None else None

            def errors(segments, key):
                return [round(100 * (seg[key] / m - 1), 2) for seg, m in zip(segments, true) if seg.get(key) is not None]

            covered = [abs(seg["mass_kg"] - m) <= 2 * seg["mass_uncertainty_kg"]
                       for seg, m in zip(mass.segments, true) if seg.get("mass_kg") is not None]
            lines.append(result(f"estimation_accuracy_{name}_{world}", rmse["gradient_smooth_pct"]["outside"], "%-pt RMSE",
                                "paper fusion (8)", rmse["gradient_paper_pct"]["outside"], gradient_rmse=rmse,
                                mass_error_pct={"ls_old": errors(mass.segments, "mass_ls_kg"),
                                                "joint_imu": errors(mass.segments, "mass_imu_kg"),
                                                "joint_gradient": errors(mass.segments, "mass_gradient_kg"),
                                                "final": errors(mass.segments, "mass_kg"),
                                                "final_after_one_weighing": (errors(calibrated.segments, "mass_kg")
                                                                             if calibrated else None)},
                                truth_within_2_sigma=f"{sum(covered)}/{len(covered)}",
                                road_load={k: v["value"] for k, v in mass.road_load.items()
                                           if isinstance(v, dict) and "value" in v},
                                map_gated_km=gradient.smoother["map_gated_km"]))
    return lines


BENCHMARKS.append(bench_estimation_accuracy)
