"""Realism levels of the virtual truck: an engineered road in its own terrain, a DEM with errors,
sensors with errors, all seeded and written beside the log as truth; bad options are one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from haulprofile.analysis.dem import open_dem
from haulprofile.analysis.dem.srtm import read_hgt
from haulprofile.analysis.errors import UserError
from haulprofile.analysis.virtual_truck import drive, load_scenario, realism_level, write_dem, write_truth
from haulprofile.analysis.virtual_truck import road_design as eng
from haulprofile.analysis.virtual_truck.scenario import ScenarioFileError
from haulprofile.analysis.virtual_truck.sensors import G_MPS2
from test_virtual_truck import SHORT


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    path = tmp_path_factory.mktemp("scenario") / "short.toml"
    path.write_text(SHORT)
    return load_scenario(path)


@pytest.fixture(scope="module")
def typical(scenario):
    return drive(scenario, seed=2, realism="typical")


@pytest.mark.parametrize("level, sizes, message", [
    ("medium", {}, "unknown realism level 'medium'"),
    ("typical", {"wheel_scale_pct": -1.0}, "cannot be negative"),
    ("harsh", {"imu_pitch": 1.0}, "unknown error size 'imu_pitch'"),
    ("typical", {"dem_noise_m": "big"}, "expected a number"),
])
def test_bad_realism_options_are_one_line_errors(level, sizes, message):
    with pytest.raises(UserError, match=message) as caught:
        realism_level(level, **sizes)
    assert "\n" not in str(caught.value)


def test_bad_realism_table_in_a_scenario_file_names_the_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(SHORT + '\n[realism]\nlevel = "typical"\ndem_noise_m = -2.0\n')
    with pytest.raises(ScenarioFileError, match=r"bad.toml \[realism\]: realism.dem_noise_m: .*negative"):
        load_scenario(path)
    path.write_text(SHORT + '\n[realism]\nlevel = "harsh"\ndem_noise_m = 0.5\n')
    level = load_scenario(path).realism
    assert level.level == "harsh" and level.dem_noise_m == 0.5 and level.wheel_scale_pct == 3.0


def test_ideal_is_the_default_and_the_old_world(scenario):
    ideal = drive(scenario, seed=2)
    assert ideal.realism.is_ideal and ideal.road.structure is None
    assert ideal.truth.equals(drive(scenario, seed=2, realism="ideal").truth)


def test_a_realistic_drive_is_reproducible(scenario, typical):
    again = drive(scenario, seed=2, realism="typical")
    assert typical.truth.equals(again.truth)
    for name in ("imu", "barometer", "gps", "engine", "wheel_speed"):
        assert typical.sensors[name].equals(again.sensors[name]), name
    assert typical.injected == again.injected
    other = drive(scenario, seed=3, realism="typical")
    assert not np.allclose(other.road.height_m, typical.road.height_m)


def test_the_road_is_engineered_into_the_terrain(typical):
    road = typical.road
    max_grade, _ = eng.road_class(np.array([60.0]))
    assert np.max(np.abs(road.gradient_pct)) <= max_grade[0] + 1e-6
    cover = road.natural_cover_m
    structure = road.structure
    assert np.all(structure[cover > eng.MAX_CUT_M] == eng.TUNNEL)
    assert np.all(np.isin(structure[cover < -eng.MAX_FILL_M], (eng.BRIDGE, eng.TUNNEL)))
    assert np.all(structure[(road.distance_m > 2300) & (road.distance_m < 3300)] == eng.TUNNEL)
    outside = (structure == eng.CUTTING) | (structure == eng.EMBANKMENT)
    assert np.max(np.abs(road.cover_m[outside])) < 0.5 * np.max(np.abs(cover[outside])), "earthworks cut/fill"
    truth = typical.truth
    assert np.all(truth["in_tunnel"].to_numpy() == (road.at(structure == eng.TUNNEL, truth["distance_m"]) > 0.5))


def test_the_dem_holds_terrain_with_errors_not_the_road(typical, tmp_path):
    tiles = write_dem(typical, tmp_path / "dem")
    dem = open_dem(tmp_path / "dem")
    truth = typical.truth
    moving = truth["speed_mps"].to_numpy() > 1
    heights = dem.height_m(truth["latitude_deg"].to_numpy()[moving], truth["longitude_deg"].to_numpy()[moving])
    error = heights - truth["terrain_height_m"].to_numpy()[moving]
    rmse = np.sqrt(np.nanmean(error ** 2))
    assert 1.0 < rmse < 15.0, rmse
    inside = truth["in_tunnel"].to_numpy()[moving]
    assert np.nanmean(heights[inside] - truth["road_height_m"].to_numpy()[moving][inside]) > 10.0, "the mountain"
    harsh = drive(typical.scenario, seed=2, realism=realism_level("harsh", dem_void_fraction=0.05))
    raw = np.concatenate([read_hgt(p).ravel() for p in write_dem(harsh, tmp_path / "harsh")])
    assert np.any(np.isnan(raw)) and len(tiles) >= 1, "voids (-32768) read back as NaN"


def test_sensors_carry_the_injected_errors(typical):
    injected, truth, s = typical.injected, typical.states, typical.sensors
    wheel = s["wheel_speed"]
    true = np.interp(wheel["time_s"], truth["time_s"], truth["speed_mps"])
    fast = true > 10
    ratio = np.median(wheel["speed_mps"][fast] / true[fast])
    assert ratio == pytest.approx(1 + injected["wheel_speed_scale"], abs=2e-3)
    imu = s["imu"]
    standing = np.interp(imu["time_s"], truth["time_s"], truth["stop"].astype(float)) > 0.99
    flat_pitch = np.degrees(np.arcsin(np.median(imu["accel_x_mps2"][standing][:200]) / G_MPS2))
    road_pitch = np.degrees(np.arctan(truth["gradient_pct"].iloc[0] / 100))
    bias_deg = np.degrees(4 * 0.05 / G_MPS2)  # the ideal sensor's per-drive bias, 4 sigma
    assert flat_pitch - road_pitch == pytest.approx(injected["imu_mount_pitch_deg"], abs=bias_deg)
    assert 0.5 <= abs(injected["imu_mount_pitch_deg"]) <= 1.0
    gps = s["gps"]
    assert injected["gps_outage_s"] == pytest.approx(0, abs=1) or np.any(gps["fix_quality"] == 0)
    assert abs(injected["torque_report_gain"]) <= 0.03 and injected["imu_mount_pitch_deg"] != 0


def test_truth_files_explain_the_drive(typical, tmp_path):
    import pandas as pd
    paths = {p.name: p for p in write_truth(typical, tmp_path)}
    grid = pd.read_csv(paths["truth-road-10m.csv"])
    assert len(grid) == int(typical.road.length_m // 10)
    assert set(grid["structure"]) >= {"tunnel"} and set(grid["structure"]) <= set(eng.STRUCTURES)
    step = np.diff(grid["road_height_m"])
    gradient = grid["gradient_pct"].to_numpy()
    assert np.allclose(step / 10 * 100, 0.5 * (gradient[1:] + gradient[:-1]), atol=0.05)
    mass = pd.read_csv(paths["truth-mass.csv"])
    assert len(mass) >= 2 and mass["mass_kg"].iloc[0] == typical.truth["mass_kg"].iloc[0]
    errors = json.loads(paths["truth-errors.json"].read_text())
    assert errors["realism_level"] == "typical"
    for key in ("dem_correlated_m", "imu_mount_pitch_deg", "wheel_speed_scale", "torque_report_gain", "wind_speed_mps"):
        assert key in errors


def test_wind_enters_the_road_load_and_the_kernel_matches_its_reference(scenario):
    from haulprofile.analysis import road_load
    from haulprofile.analysis.virtual_truck.driver import simulate_kernel
    from haulprofile.analysis.virtual_truck.world import build_road
    from haulprofile.analysis.virtual_truck.truck import scenario_vehicle, simulate
    road = build_road(scenario, 2, realism_level("typical"))
    vehicle = scenario_vehicle(scenario)
    wind = 6.0 * np.sin(road.distance_m / 700.0)
    compiled = simulate(scenario, vehicle, road, head_wind_mps=wind)
    reference = simulate(scenario, vehicle, road, kernel=simulate_kernel.py_func, head_wind_mps=wind)
    for column in compiled.columns:
        assert np.allclose(compiled[column].to_numpy(float), reference[column].to_numpy(float),
                           rtol=1e-9, atol=1e-6), column
    moving = (compiled["speed_mps"] > 1.0).to_numpy()
    v = compiled["speed_mps"].to_numpy()[moving]
    air = v + road.at(wind, compiled["distance_m"].to_numpy()[moving])
    calm = road_load.wheel_force_n(v, compiled["accel_mps2"].to_numpy()[moving],
                                   compiled["gradient_pct"].to_numpy()[moving], compiled["mass_kg"].to_numpy()[moving],
                                   vehicle)
    drag = 0.5 * road_load.AIR_DENSITY_KGPM3 * vehicle.drag_coefficient * vehicle.frontal_area_m2
    expected = calm + drag * (air * np.abs(air) - v * v)
    assert np.allclose(expected, compiled["wheel_force_n"].to_numpy()[moving], rtol=1e-6, atol=1e-3)


def test_the_gusts_redrawn_alone_keep_the_mean_wind_and_every_other_draw(scenario, typical):
    from haulprofile.analysis.virtual_truck.disturbances import GUST_LENGTH_M, _gusts, head_wind_mps
    level, road = realism_level("typical"), typical.road
    own, own_sizes = head_wind_mps(road, level, rng := np.random.default_rng(7))
    after_own = rng.standard_normal(5)
    other, other_sizes = head_wind_mps(road, level, rng := np.random.default_rng(7), np.random.default_rng(1))
    assert other_sizes == own_sizes and np.array_equal(rng.standard_normal(5), after_own)
    # what differs is the gusts alone: each series less its own gusts is the same mean head wind
    phi = np.exp(-(road.distance_m[1] - road.distance_m[0]) / GUST_LENGTH_M)
    drawn = np.random.default_rng(7)
    drawn.uniform(size=2)
    own_gusts = _gusts(road.distance_m.size, phi, drawn)
    other_gusts = _gusts(road.distance_m.size, phi, np.random.default_rng(1))
    assert not np.allclose(own_gusts, other_gusts)
    assert np.allclose(own - level.wind_gust_mps * own_gusts, other - level.wind_gust_mps * other_gusts, atol=1e-12)
    redrawn = drive(scenario, seed=2, realism="typical", gust_seed=1)
    assert redrawn.injected["gust_seed"] == 1
    for name in ("wind_speed_mps", "wind_towards_deg", "torque_report_gain", "torque_report_offset_pct",
                 "wheel_speed_scale", "imu_mount_pitch_deg"):
        assert redrawn.injected[name] == typical.injected[name], name
    assert not np.allclose(redrawn.states["head_wind_mps"].to_numpy()[:1000],
                           typical.states["head_wind_mps"].to_numpy()[:1000])
