"""Gradient estimation on a synthetic drive built with the vehicle model (own test material,
independent of the virtual truck): known road, terrain DEM with a tunnel, noisy sensors."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import road_load
from haulprofile.analysis.dem.srtm import SrtmDem, write_hgt
from haulprofile.analysis.errors import UserError
from haulprofile.analysis.geodesy import EARTH_RADIUS_M
from haulprofile.analysis.gradient import estimate_gradient
from haulprofile.analysis.gradient import grid as distance_grid
from haulprofile.analysis.gradient import sources
from haulprofile.analysis.gradient.stage import GradientOptions, gradient_stage
from haulprofile.analysis.kinematics import acceleration_mps2
from haulprofile.analysis.pipeline import Options, RunContext
from haulprofile.analysis.vehicle import load_vehicle

LAT0, LON0 = 47.5, 11.02
M_PER_DEG_LON = np.radians(1) * EARTH_RADIUS_M * np.cos(np.radians(LAT0))
TUNNEL_M = (9_000.0, 10_500.0)


def road_height_m(s):
    return 500 + 40 * np.sin(s / 1500) + 15 * np.sin(s / 600 + 1) + 2 * np.sin(s / 300)


def terrain_height_m(s):
    """Terrain over the road: a 40 m hill over the tunnel, a few metres of cut and fill elsewhere."""
    over_tunnel = 40 * np.clip(np.minimum(s - TUNNEL_M[0], TUNNEL_M[1] - s) / 300, 0, 1)
    return road_height_m(s) + over_tunnel + 1.0 * np.sin(s / 60 + 2)


def write_route_dem(directory):
    n = 1201
    lon = 11 + np.arange(n) / (n - 1)
    heights = terrain_height_m((lon - LON0) * M_PER_DEG_LON)
    write_hgt(directory / "N47E011.hgt", np.repeat(heights[None, :], n, axis=0))
    return directory


def synthetic_drive(seed=1, duration_s=1800.0, mass_kg=20_000.0, vehicle_name="rigid-18t", rate_hz=10.0,
                    stops_s=(600.0,), stop_duration_s=90.0, mass_after_stop_kg=None):
    """A 10 Hz signals table with truth columns (true_*) from the shared vehicle model."""
    rng = np.random.default_rng(seed)
    vehicle = load_vehicle(vehicle_name)
    time = np.arange(0, duration_s, 1 / rate_hz)
    target = 17 + 5 * np.sin(time / 90) + 3 * np.sin(time / 23 + 1)
    for stop in stops_s:
        ramp = np.clip(np.minimum(np.abs(time - stop) - stop_duration_s / 2, 1e9) / 40, 0, 1)
        target = target * ramp
    target *= np.clip(time / 40, 0, 1)
    speed = pd.Series(target).rolling(int(10 * rate_hz), center=True, min_periods=1).mean().to_numpy()
    speed = np.maximum(speed, 0)
    accel = np.gradient(speed, time)
    distance = np.concatenate([[0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) / rate_hz)])
    gradient = 100 * np.interp(distance, *_road_slope_table(distance.max()))
    mass = np.full(len(time), mass_kg)
    if mass_after_stop_kg is not None:
        mass[time > stops_s[0]] = mass_after_stop_kg
    force = road_load.wheel_force_n(speed, accel, gradient, mass, vehicle)
    ratios = np.array(vehicle.total_ratios)
    engine_rpm_per_mps = ratios * 60 / (2 * np.pi * vehicle.wheel_radius_m)
    gear = np.array([int(np.argmax(v * engine_rpm_per_mps < 1500)) for v in speed])
    ratio = ratios[gear]
    engine_speed = speed * ratio * 60 / (2 * np.pi * vehicle.wheel_radius_m)
    engine_torque = force * vehicle.wheel_radius_m / (vehicle.driveline_efficiency * ratio)
    shifting = np.convolve(np.abs(np.diff(gear, prepend=gear[0])) > 0, np.ones(int(rate_hz)), "same") > 0
    engine_torque[shifting] = 0.0
    brake = force < -2000
    engine_torque = np.where(brake, 0.0, engine_torque)
    lat = LAT0 + rng.normal(0, 1.5, len(time)) / 111_000
    lon = LON0 + (distance + rng.normal(0, 1.5, len(time))) / M_PER_DEG_LON
    in_tunnel = (distance > TUNNEL_M[0]) & (distance < TUNNEL_M[1])
    h_acc = np.where(in_tunnel, 40.0, 1.5 + rng.uniform(0, 1, len(time)))
    height = road_height_m(distance)
    pressure = 101325 * (1 - height / 44330.8) ** 5.255 + rng.normal(0, 2.0, len(time)) + 0.02 * time / 60
    frame = pd.DataFrame({
        "time_s": time, "speed_mps": speed + rng.normal(0, 0.02, len(time)),
        "latitude_deg": lat, "longitude_deg": lon, "gps_h_acc_m": h_acc, "gps_v_acc_m": 1.5 * h_acc,
        "pressure_pa": pressure, "accel_x_mps2": accel + 9.81 * np.sin(np.arctan(gradient / 100))
        + rng.normal(0, 0.2, len(time)),
        "engine_speed_rpm": engine_speed * (1 + rng.normal(0, 0.002, len(time))),
        "engine_torque_nm": engine_torque * (1 + rng.normal(0, 0.01, len(time))),
        "current_gear": gear + 1, "brake_switch": brake.astype(float),
        "true_gradient_pct": gradient, "true_height_m": height, "true_mass_kg": mass,
        "in_tunnel": in_tunnel,
    })
    frame["distance_m"] = np.concatenate([[0], np.cumsum(0.5 * (frame.speed_mps.to_numpy()[1:]
                                                               + frame.speed_mps.to_numpy()[:-1]) / rate_hz)])
    frame["accel_mps2"] = acceleration_mps2(time, frame["speed_mps"].to_numpy())
    return frame


def _road_slope_table(s_max):
    s = np.linspace(0, s_max + 100, int((s_max + 100) / 0.5) + 2)
    return s, np.gradient(road_height_m(s), s)


def grid_rmse(result, frame, mask_fn):
    grid = result.grid
    s = grid["distance_m"].to_numpy()
    truth = 100 * np.interp(s, *_road_slope_table(s.max()))
    inside = (s > TUNNEL_M[0]) & (s < TUNNEL_M[1])
    keep = mask_fn(inside) & (s > 200) & (s < s.max() - 200)
    error = grid["gradient_pct"].to_numpy()[keep] - truth[keep]
    return float(np.sqrt(np.mean(error ** 2)))


@pytest.fixture(scope="module")
def drive():
    return synthetic_drive()


@pytest.fixture(scope="module")
def dem(tmp_path_factory):
    return SrtmDem(write_route_dem(tmp_path_factory.mktemp("dem")))


def test_local_linear_is_exact_on_a_line_even_one_sided():
    s = np.arange(200) * 10.0
    height = 3.0 + 0.04 * s
    weight = np.where((s > 700) & (s < 900), 0.0, 1.0)
    level, slope, support = distance_grid.local_linear(height, weight, 10.0, 50.0)
    np.testing.assert_allclose(slope, 0.04, rtol=1e-9)
    np.testing.assert_allclose(level, height, rtol=1e-9)
    assert support[80] < 0.1 < support[20]


def test_barometric_formula_matches_standard_atmosphere():
    # ISA: 1000 m above sea level is 89 874.6 Pa (ICAO Doc 7488 table).
    assert sources.barometric_height_m(89_874.6) == pytest.approx(1000.0, abs=0.5)
    assert sources.barometric_height_m(101_325.0) == pytest.approx(0.0, abs=1e-9)


def test_map_weight_follows_the_accuracy_rule():
    np.testing.assert_allclose(sources.map_weight([0, 5, 20, np.nan], [0, 3, 1, 1]), [1, 0.5, 0, 0])


def test_gps_outlier_kernel_matches_reference():
    east = np.array([0, 10, 20, 500, 40, 50, np.nan, 70.0])
    north = np.zeros(8)
    distance = np.arange(8) * 10.0
    time = np.arange(8.0)
    expected = [False, False, False, True, False, False, True, False]
    for fn in (sources.gps_outliers, sources.gps_outliers.py_func):
        np.testing.assert_array_equal(fn(east, north, distance, time, 25.0, 30.0), expected)


def test_fusion_meets_accuracy_outside_and_inside_tunnel(drive, dem):
    result = estimate_gradient(drive, dem)
    outside = grid_rmse(result, drive, lambda inside: ~inside)
    tunnel = grid_rmse(result, drive, lambda inside: inside)
    assert outside <= 0.3, outside
    assert tunnel <= 0.6, tunnel
    assert result.grid["weight_map"].to_numpy()[int(9_700 / 10)] < 0.05


def test_fused_height_integrates_to_fused_gradient(drive, dem):
    grid = estimate_gradient(drive, dem).grid
    height = grid["height_m"].to_numpy()
    np.testing.assert_allclose(np.diff(height), 0.5 * np.diff(grid["distance_m"]) *
                               (grid["gradient_pct"].to_numpy()[1:] + grid["gradient_pct"].to_numpy()[:-1]) / 100,
                               atol=1e-9)
    s = grid["distance_m"].to_numpy()
    assert np.nanmedian(np.abs(height - road_height_m(s))) < 5.0


def fallback_stage(drive, dem_dir, said):
    ctx = RunContext(inputs=[], out_dir=".", signals=drive.copy(), dem_dir=dem_dir, say=said.append,
                     options=Options(gradient=GradientOptions(barometer_off_map=True)))
    return gradient_stage(ctx)


def test_baro_only_without_dem_and_missing_tile_falls_back(drive, tmp_path):
    said = []
    result = fallback_stage(drive, None, said)
    assert "gradient_map_pct" not in result.grid and grid_rmse(result, drive, lambda i: ~i | i) < 0.5
    other = tmp_path / "elsewhere"
    other.mkdir()
    write_hgt(other / "N10E010.hgt", np.zeros((1201, 1201)))
    result = fallback_stage(drive, other, said)
    assert any("N47E011" in s and "barometer alone" in s for s in said)


def test_survives_nans_gaps_jumps_and_a_stopped_barometer(drive, dem):
    broken = drive.copy()
    n = len(broken)
    broken.loc[1000:1300, ["latitude_deg", "longitude_deg"]] = np.nan
    broken.loc[3000:3050, "latitude_deg"] += 0.01
    broken.loc[n // 2:, "pressure_pa"] = broken["pressure_pa"].iloc[n // 2]
    broken.loc[5000:5100, "speed_mps"] = np.nan
    result = estimate_gradient(broken, dem)
    assert any("GPS fixes left out" in note for note in result.notes)
    assert any("barometer missing" in note for note in result.notes)
    assert np.isfinite(result.grid["gradient_pct"]).all()
    assert grid_rmse(result, broken, lambda inside: ~inside) < 0.5


def test_no_source_or_no_valid_sample_is_a_clear_error(drive):
    with pytest.raises(UserError, match="has none"):
        estimate_gradient(drive.drop(columns=["pressure_pa"]), None)
    empty = drive.assign(valid=False)
    with pytest.raises(UserError, match="no valid samples"):
        estimate_gradient(empty, None)


def test_gps_altitude_alone_gives_a_gradient_with_an_honest_uncertainty(drive):
    """A GPS-only log (no DEM, no barometer, no IMU): GPS altitude errors of 4 m correlated over
    30 s; the smoothed slope beats differencing over 200 m and its stated sigma holds."""
    rng = np.random.default_rng(7)
    n, phi = len(drive), np.exp(-0.1 / 30.0)
    noise = np.empty(n)
    noise[0] = rng.normal(0, 4.0)
    shocks = rng.normal(0, 4.0 * np.sqrt(1 - phi ** 2), n)
    for k in range(1, n):
        noise[k] = phi * noise[k - 1] + shocks[k]
    log = drive.drop(columns=["pressure_pa", "accel_x_mps2"]).assign(
        gps_altitude_m=drive["true_height_m"] + noise, gps_v_acc_m=4.0)
    result = estimate_gradient(log, None)
    assert any("only height source" in note for note in result.notes)
    grid = result.grid
    s = grid["distance_m"].to_numpy()
    truth = 100 * np.interp(s, *_road_slope_table(s.max()))
    keep = (s > 200) & (s < s.max() - 200)
    error = grid["gradient_pct"].to_numpy()[keep] - truth[keep]
    heights = np.interp(s, log["distance_m"], log["gps_altitude_m"])
    naive = 100 * (heights[20:] - heights[:-20]) / 200 - 100 * np.interp(s[10:-10], *_road_slope_table(s.max()))
    assert np.sqrt(np.mean(error ** 2)) < 0.6 * np.sqrt(np.mean(naive ** 2))
    inside = np.mean(np.abs(error) <= 2 * grid["gradient_smooth_std_pct"].to_numpy()[keep])
    assert 0.85 <= inside <= 0.995
    assert np.isnan(grid["gradient_paper_pct"]).all()


def test_gps_altitude_with_only_its_dilution_of_precision_is_weighed_by_it(drive):
    """A receiver never asked for GST (a u-blox 7's default) states VDOP, not v_acc: the gradient
    takes VDOP times the datasheet's range error as the accuracy (before: "needs ... GPS altitude
    with its accuracy"), the same estimate as a receiver stating that accuracy."""
    from haulprofile.analysis.gnss_accuracy import DATASHEET_RANGE_SIGMA_M

    rng = np.random.default_rng(7)
    base = drive.drop(columns=["pressure_pa", "accel_x_mps2", "gps_v_acc_m", "gps_h_acc_m"], errors="ignore").assign(
        gps_altitude_m=drive["true_height_m"] + np.convolve(rng.normal(0, 4.0, len(drive)), np.ones(50) / 50, "same"))
    stated = estimate_gradient(base.assign(gps_v_acc_m=4.0), None)
    from_dop = estimate_gradient(base.assign(gps_vdop=4.0 / DATASHEET_RANGE_SIGMA_M), None)
    assert any("dilution of precision" in note for note in from_dop.notes)
    assert np.allclose(from_dop.grid["gradient_pct"], stated.grid["gradient_pct"])
    assert np.allclose(from_dop.grid["gradient_smooth_std_pct"], stated.grid["gradient_smooth_std_pct"])


def test_imu_gradient_is_reported(drive, dem):
    grid = estimate_gradient(drive, dem).grid
    assert "gradient_imu_pct" in grid and np.isfinite(grid["gradient_imu_pct"]).mean() > 0.9


def test_a_standstill_shows_how_far_the_imu_bias_moved():
    """Standing, the specific force along x is g sin(alpha) + bias: its change between the
    standstill's first and last 20 s is the bias's (here 0.012 m/s² over 10 minutes, in noise of
    0.05 m/s² per sample), with the variance of that difference; a standstill too short to tell
    has none, and driving between standstills counts in neither."""
    rng = np.random.default_rng(1)
    time_s = np.arange(0.0, 900.0, 0.1)
    speed = np.where((time_s > 100) & (time_s < 700), 0.0, 12.0)
    speed[(time_s > 800) & (time_s < 803)] = 0.0
    bias = 0.3 + 0.012 * np.clip((time_s - 100) / 600, 0, 1)
    force = 9.80665 * np.sin(0.02) + bias + rng.normal(0, 0.05, len(time_s))
    changes = sources.standstill_bias_changes(time_s, speed, force)
    assert len(changes) == 1
    start, change, variance = changes[0]
    assert time_s[start] == pytest.approx(100.1, abs=0.15)
    assert abs(change - 0.012 * (1 - 24 / 600)) <= 3 * np.sqrt(variance)
    assert 0.001 < np.sqrt(variance) < 0.01
