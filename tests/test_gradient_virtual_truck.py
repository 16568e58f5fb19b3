"""Gradient accuracy on the three shipped virtual-truck scenarios (fixed seeds), against the
issue's targets: RMSE <= 0.3 %-points on the 10 m grid outside the tunnel, <= 0.6 inside."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.kinematics import acceleration_mps2, distance_m

virtual_truck = pytest.importorskip("haulprofile.analysis.virtual_truck")

SCENARIO_SEEDS = {"regional-tunnel": 0, "long-haul": 0, "urban-delivery": 0}


def _bin_mean(stream_time, values, time_s):
    """Mean of a stream's samples within each 10 Hz bin [t - 0.05, t + 0.05) (NaN where none)."""
    edges = np.concatenate([time_s - 0.05, [time_s[-1] + 0.05]])
    index = np.searchsorted(edges, stream_time, side="right") - 1
    ok = (index >= 0) & (index < len(time_s)) & np.isfinite(values)
    total = np.bincount(index[ok], weights=values[ok], minlength=len(time_s))
    count = np.bincount(index[ok], minlength=len(time_s))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def _held(stream_time, values, time_s, max_hold_s=1.0):
    """Latest sample at or before each time, if not older than ``max_hold_s``."""
    index = np.searchsorted(stream_time, time_s, side="right") - 1
    out = np.asarray(values, dtype=float)[np.clip(index, 0, None)]
    age = time_s - stream_time[np.clip(index, 0, None)]
    return np.where((index >= 0) & (age <= max_hold_s), out, np.nan)


def signals_from_drive(drive) -> pd.DataFrame:
    """A 10 Hz signals table from the virtual truck's sensor streams, as ingest aligns them
    (bin means for fast streams, slow streams held for at most 1 s)."""
    time_s = drive.truth["time_s"].to_numpy()
    s = drive.sensors
    wheel, engine, gps = s["wheel_speed"], s["engine"], s["gps"]
    frame = pd.DataFrame({"time_s": time_s})
    frame["speed_mps"] = _held(wheel.time_s.to_numpy(), wheel.speed_mps, time_s)
    frame["brake_switch"] = _held(wheel.time_s.to_numpy(), wheel.brake_switch, time_s)
    frame["engine_speed_rpm"] = _bin_mean(engine.time_s.to_numpy(), engine.engine_speed_rpm.to_numpy(), time_s)
    frame["engine_torque_nm"] = _bin_mean(engine.time_s.to_numpy(), engine.actual_engine_torque_pct.to_numpy()
                                          * s["engine_reference_torque_nm"] / 100, time_s)
    frame["current_gear"] = _held(s["transmission"].time_s.to_numpy(), s["transmission"].current_gear, time_s)
    for column, source in (("latitude_deg", "latitude_deg"), ("longitude_deg", "longitude_deg"),
                           ("gps_altitude_m", "altitude_m"), ("gps_h_acc_m", "h_acc_m"), ("gps_v_acc_m", "v_acc_m")):
        frame[column] = _held(gps.time_s.to_numpy(), gps[source], time_s)
    frame["pressure_pa"] = _bin_mean(s["barometer"].time_s.to_numpy(), s["barometer"].pressure_pa.to_numpy(), time_s)
    frame["air_temperature_c"] = _held(s["humidity"].time_s.to_numpy(), s["humidity"].temperature_c, time_s)
    frame["accel_x_mps2"] = _bin_mean(s["imu"].time_s.to_numpy(), s["imu"].accel_x_mps2.to_numpy(), time_s)
    frame["reported_mass_kg"] = _held(s["weight"].time_s.to_numpy(), s["weight"].gross_combination_weight_kg,
                                      time_s, 1.5)
    speed = np.nan_to_num(frame["speed_mps"].to_numpy())
    frame["distance_m"] = distance_m(time_s, speed)
    frame["accel_mps2"] = acceleration_mps2(time_s, speed)
    return frame


def gradient_errors(result, truth):
    """RMSE [%-points] of the fused gradient on the grid, outside and inside tunnels (NaN if none)."""
    grid = result.grid
    s = grid["distance_m"].to_numpy()
    true_distance = truth["distance_m"].to_numpy()
    order = np.argsort(true_distance, kind="stable")
    truth_on_grid = np.interp(s, true_distance[order], truth["gradient_pct"].to_numpy()[order])
    tunnel = np.interp(s, true_distance[order], truth["in_tunnel"].to_numpy(float)[order]) > 0.5
    error = grid["gradient_pct"].to_numpy() - truth_on_grid
    rmse = {}
    for name, mask in (("outside", ~tunnel), ("tunnel", tunnel)):
        rmse[name] = float(np.sqrt(np.nanmean(error[mask] ** 2))) if mask.any() else float("nan")
    return rmse


_DRIVES: dict = {}


def virtual_drive_data(name: str, tmp_path_factory):
    """(signals table, truth, DEM) of a shipped scenario on its fixed seed, built once per session."""
    if name not in _DRIVES:
        from haulprofile.analysis.dem import open_dem
        drive = virtual_truck.drive(virtual_truck.load_scenario(name), seed=SCENARIO_SEEDS[name])
        directory = tmp_path_factory.mktemp(f"dem-{name}")
        virtual_truck.write_dem(drive, directory)
        _DRIVES[name] = (signals_from_drive(drive), drive.truth, open_dem(directory))
    return _DRIVES[name]


@pytest.fixture(scope="module", params=sorted(SCENARIO_SEEDS))
def scenario_data(request, tmp_path_factory):
    return request.param, virtual_drive_data(request.param, tmp_path_factory)


def test_gradient_meets_targets_outside_and_inside_the_tunnel(scenario_data):
    from haulprofile.analysis.gradient import estimate_gradient
    name, (signals, truth, dem) = scenario_data
    result = estimate_gradient(signals, dem)
    rmse = gradient_errors(result, truth)
    print(name, rmse)
    assert rmse["outside"] <= 0.3, (name, rmse)
    if name == "regional-tunnel":
        assert rmse["tunnel"] <= 0.6, (name, rmse)
        in_tunnel = np.interp(result.grid["distance_m"], truth["distance_m"], truth["in_tunnel"].astype(float)) > 0.5
        assert np.median(result.grid["weight_map"][in_tunnel]) < 0.05


def test_gradient_without_dem_is_barometric_and_still_on_target(scenario_data):
    from haulprofile.analysis.gradient import estimate_gradient
    name, (signals, truth, _) = scenario_data
    rmse = gradient_errors(estimate_gradient(signals, None), truth)
    assert rmse["outside"] <= 0.3, (name, rmse)


def test_imu_gradient_is_worse_than_the_barometer_as_in_the_paper(scenario_data):
    from haulprofile.analysis.gradient import estimate_gradient
    name, (signals, truth, dem) = scenario_data
    grid = estimate_gradient(signals, dem).grid
    true = np.interp(grid["distance_m"], truth["distance_m"], truth["gradient_pct"])
    imu = np.sqrt(np.nanmean((grid["gradient_imu_pct"] - true) ** 2))
    baro = np.sqrt(np.nanmean((grid["gradient_baro_pct"] - true) ** 2))
    assert baro < imu, (name, baro, imu)


def test_survives_a_dead_barometer_gps_jumps_and_a_gap_on_the_regional_drive(tmp_path_factory):
    from haulprofile.analysis.gradient import estimate_gradient
    from haulprofile.analysis.mass import estimate_mass
    signals, truth, dem = virtual_drive_data("regional-tunnel", tmp_path_factory)
    broken = signals.copy()
    n = len(broken)
    broken.loc[n // 2:, "pressure_pa"] = np.nan
    broken.loc[3000:3030, "longitude_deg"] += 0.003
    broken.loc[6000:6100, ["speed_mps", "engine_torque_nm"]] = np.nan
    result = estimate_gradient(broken, dem)
    assert any("GPS fixes left out" in note for note in result.notes)
    assert any("barometer missing" in note for note in result.notes)
    assert gradient_errors(result, truth)["outside"] <= 0.3
    vehicle = virtual_truck.scenario_vehicle(virtual_truck.load_scenario("regional-tunnel"))
    mass = estimate_mass(broken.assign(**result.samples), vehicle)
    time_s, true_mass = truth["time_s"].to_numpy(), truth["mass_kg"].to_numpy()
    for segment in mass.segments:
        if segment["status"] == "ok":
            inside = (time_s >= segment["start_s"]) & (time_s <= segment["end_s"])
            assert abs(segment["mass_ls_kg"] / np.median(true_mass[inside]) - 1) <= 0.06
