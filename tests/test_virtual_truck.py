"""The virtual truck is physically consistent, deterministic, and its files read back."""

from __future__ import annotations

import numpy as np
import pytest

from haulprofile.analysis import road_load
from haulprofile.analysis.dem.srtm import SrtmDem, read_hgt, tile_origin
from haulprofile.analysis.virtual_truck import SCENARIOS, TRUTH_COLUMNS, drive, load_scenario, write_dem
from haulprofile.analysis.virtual_truck.driver import simulate_kernel
from haulprofile.analysis.virtual_truck.world import build_road
from haulprofile.analysis.virtual_truck.truck import scenario_vehicle, simulate

SHORT = """
[scenario]
name = "short-tunnel"
vehicle = "rigid-18t"
start_latitude_deg = 47.5
start_longitude_deg = 8.5
start_heading_deg = 30.0
start_time = 2025-05-14T06:30:00Z

[route]
initial_stop_s = 5.0
final_stop_s = 5.0

[[route.section]]
length_m = 1500
speed_kmh = 60
stop_s = 20

[[route.section]]
length_m = 3000
speed_kmh = 70

[[route.section]]
length_m = 500
speed_kmh = 40

[terrain]
hill_amplitude_m = 30.0
hill_wavelengths_m = [2000.0, 5000.0]

[[tunnel]]
start_m = 2200.0
length_m = 1200.0
depth_m = 40.0

[payload]
initial_kg = 5000.0
after_stop_kg = [1000.0]
"""


@pytest.fixture(scope="module")
def short_scenario(tmp_path_factory):
    path = tmp_path_factory.mktemp("scenario") / "short.toml"
    path.write_text(SHORT)
    return load_scenario(path)


@pytest.fixture(scope="module")
def short_drive(short_scenario):
    return drive(short_scenario, seed=3)


@pytest.fixture(scope="module")
def short_dem(short_drive, tmp_path_factory):
    directory = tmp_path_factory.mktemp("dem")
    return directory, write_dem(short_drive, directory)


def test_truth_has_the_documented_columns_at_10_hz(short_drive):
    truth = short_drive.truth
    assert tuple(truth.columns) == TRUTH_COLUMNS
    assert np.allclose(np.diff(truth["time_s"]), 0.1)
    overspeed = short_drive.scenario.driver.downhill_overspeed_kmh
    assert 0.97 * 70 / 3.6 <= truth["speed_mps"].max() <= (70 + overspeed) / 3.6 + 0.05


def test_equations_1_to_4_reproduce_the_wheel_force(short_drive):
    truth, vehicle = short_drive.truth, short_drive.vehicle
    recomputed = road_load.wheel_force_n(truth["speed_mps"], truth["accel_mps2"], truth["gradient_pct"],
                                         truth["mass_kg"], vehicle)
    scale = np.maximum(np.abs(truth["wheel_force_n"]), 1000.0)
    assert np.max(np.abs(recomputed - truth["wheel_force_n"]) / scale) < 0.005
    accel = road_load.acceleration_mps2(truth["wheel_force_n"], truth["speed_mps"], truth["gradient_pct"],
                                        truth["mass_kg"], vehicle)
    assert np.allclose(accel, truth["accel_mps2"], atol=1e-9)


def test_engine_torque_and_speed_give_the_wheel_force_in_gear(short_drive):
    truth, vehicle = short_drive.truth, short_drive.vehicle
    in_gear = (~truth["brake_active"] & ~truth["shifting"] & ~truth["clutch_slip"] & (truth["speed_mps"] > 1.0))
    assert in_gear.mean() > 0.4
    torque = road_load.wheel_torque_from_engine_nm(truth["engine_torque_nm"], truth["engine_speed_rpm"],
                                                   truth["speed_mps"], vehicle.wheel_radius_m,
                                                   vehicle.driveline_efficiency)
    force = road_load.wheel_force_from_torque_n(torque, vehicle.wheel_radius_m)
    expected = truth["wheel_force_n"][in_gear]
    assert np.max(np.abs(force[in_gear] - expected) / np.maximum(np.abs(expected), 1000.0)) < 0.005
    ratio = 2 * np.pi * truth["engine_speed_rpm"] / 60 * vehicle.wheel_radius_m / truth["speed_mps"]
    gears = truth["gear"][in_gear].to_numpy()
    assert np.allclose(ratio[in_gear], np.asarray(vehicle.total_ratios)[gears - 1])


def test_engine_limits_and_shift_pauses(short_drive):
    states, vehicle = short_drive.states, short_drive.vehicle
    assert states["engine_torque_nm"].max() <= vehicle.engine_reference_torque_nm + 1e-9
    power = states["engine_torque_nm"] * states["engine_speed_rpm"] * np.pi / 30
    assert power.max() <= vehicle.engine.max_power_w * (1 + 1e-9)
    shifting = states["shifting"].to_numpy()
    assert np.all(states["engine_torque_nm"][shifting] == 0) and np.all(states["gear"][shifting] == 0)
    starts = np.flatnonzero(np.diff(shifting.astype(int)) == 1) + 1
    ends = np.flatnonzero(np.diff(shifting.astype(int)) == -1) + 1
    assert len(starts) >= 5
    pauses = (ends - starts) * 0.01 / vehicle.engine.shift_time_s      # back-to-back shifts join
    assert np.allclose(pauses, np.round(pauses), atol=0.011) and pauses.min() >= 0.99
    moving = states["speed_mps"] > 0
    assert states["accel_mps2"][moving].max() <= short_drive.scenario.driver.max_accel_mps2 + 1e-9
    assert states["accel_mps2"].min() >= -short_drive.scenario.driver.max_decel_mps2 - 1e-9


def test_payload_changes_only_at_stops(short_drive):
    states = short_drive.states
    changes = np.flatnonzero(np.diff(states["mass_kg"].to_numpy())) + 1
    assert len(changes) == 1
    assert states["stop"].to_numpy()[changes - 1].all() and states["stop"].to_numpy()[changes].all()
    assert states["speed_mps"].to_numpy()[changes].max() == 0.0
    curb = short_drive.vehicle.curb_mass_kg
    assert states["mass_kg"].iloc[0] == curb + 5000 and states["mass_kg"].iloc[-1] == curb + 1000


def test_stops_are_standstill_for_their_time(short_drive):
    stop = short_drive.states["stop"].to_numpy()
    edges = np.flatnonzero(np.diff(stop.astype(int)))
    durations = np.diff(np.concatenate([[-1], edges]))[::2] * 0.01
    assert durations[0] == pytest.approx(5.0, abs=0.02)
    assert durations[1] == pytest.approx(20.0, abs=0.02)
    assert short_drive.truth["speed_mps"][short_drive.truth["stop"]].max() == 0.0


def test_tunnel_road_leaves_the_terrain_and_gps_collapses(short_drive):
    truth, gps = short_drive.truth, short_drive.sensors["gps"]
    cover = truth["terrain_height_m"] - truth["road_height_m"]
    assert cover[truth["in_tunnel"]].max() == pytest.approx(40.0, abs=0.5)
    assert np.abs(cover[~truth["in_tunnel"]]).max() < 3.0
    distance = np.interp(gps["time_s"], truth["time_s"], truth["distance_m"])
    inside = (distance > 2195) & (distance < 3405)
    deep = (distance > 2350) & (distance < 3250)
    assert (gps["fix_quality"][deep] == 0).all()
    assert gps["h_acc_m"][inside & (gps["fix_quality"] > 0)].min() >= 20.0
    assert gps["h_acc_m"][~inside].max() < 5.0


def test_dem_tiles_give_back_the_terrain(short_drive, short_dem):
    directory, paths = short_dem
    assert [p.name for p in paths] == ["N47E008.hgt"]
    truth = short_drive.truth
    lat, lon = truth["latitude_deg"].to_numpy(), truth["longitude_deg"].to_numpy()
    dem_height = SrtmDem(directory).height_m(lat, lon)
    # independent bilinear reference on the exact (unrounded) field at the four grid nodes
    lat0, lon0 = tile_origin("N47E008")
    n = read_hgt(paths[0]).shape[0] - 1
    row, col = (lat0 + 1 - lat) * n, (lon - lon0) * n
    r0, c0 = np.floor(row), np.floor(col)
    fr, fc = row - r0, col - c0
    node = lambda r, c: short_drive.road.terrain_height_m(lat0 + 1 - r / n, lon0 + c / n)  # noqa: E731
    bilinear = (node(r0, c0) * (1 - fr) * (1 - fc) + node(r0, c0 + 1) * (1 - fr) * fc
                + node(r0 + 1, c0) * fr * (1 - fc) + node(r0 + 1, c0 + 1) * fr * fc)
    assert np.max(np.abs(dem_height - bilinear)) <= 0.5 + 1e-9      # SRTM stores whole metres
    interpolation = np.abs(bilinear - truth["terrain_height_m"])
    tunnel = truth["in_tunnel"].to_numpy()
    assert interpolation[~tunnel].max() < 0.5          # 3" grid (93 m x 63 m here) on smooth hills
    assert interpolation[tunnel].max() < 1.5           # the hill over the tunnel is steeper
    interpolation_error = interpolation.max()
    assert np.max(np.abs(dem_height - truth["terrain_height_m"])) <= 0.5 + interpolation_error


def test_same_seed_same_tiles_other_seed_other_tiles(short_scenario, short_dem, tmp_path):
    _, paths = short_dem
    again = write_dem(drive(short_scenario, seed=3), tmp_path / "same")
    other = write_dem(short_scenario, tmp_path / "other", seed=4)
    assert again[0].read_bytes() == paths[0].read_bytes()
    assert other[0].read_bytes() != paths[0].read_bytes()


def test_kernel_matches_its_python_reference(short_scenario):
    road = build_road(short_scenario, 3)
    vehicle = scenario_vehicle(short_scenario)
    compiled = simulate(short_scenario, vehicle, road)
    reference = simulate(short_scenario, vehicle, road, kernel=simulate_kernel.py_func)
    assert compiled.shape == reference.shape
    recomputed = road_load.wheel_force_n(reference["speed_mps"], reference["accel_mps2"], reference["gradient_pct"],
                                         reference["mass_kg"], vehicle)
    assert np.allclose(recomputed, reference["wheel_force_n"], rtol=1e-9, atol=1e-6)
    for column in compiled.columns:
        assert np.allclose(compiled[column].to_numpy(float), reference[column].to_numpy(float),
                           rtol=1e-9, atol=1e-6), column


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_shipped_scenarios_drive_at_least_30_minutes(name):
    scenario = load_scenario(name)
    states = simulate(scenario, scenario_vehicle(scenario), build_road(scenario, 0))
    assert states["time_s"].iloc[-1] >= 30 * 60
    assert states["distance_m"].iloc[-1] == pytest.approx(build_road(scenario, 0).length_m, abs=1.0)
    masses = states["mass_kg"].to_numpy()
    changes = np.flatnonzero(np.diff(masses)) + 1
    assert states["stop"].to_numpy()[changes].all()


def test_regional_scenario_has_hills_a_tunnel_and_one_payload_change():
    scenario = load_scenario("regional-tunnel")
    road = build_road(scenario, 0)
    tunnel = road.distance_m[road.in_tunnel]
    assert tunnel[-1] - tunnel[0] == pytest.approx(1500, abs=2)
    assert road.cover_m[road.in_tunnel].max() == pytest.approx(40.0, abs=0.5)
    assert 3.0 < np.abs(road.gradient_pct).max() < 8.0
    assert len(set(scenario.payload.after_stop_kg) | {scenario.payload.initial_kg}) == 2


def test_a_vecto_cycle_becomes_a_route(data_dir, tmp_path):
    cycle = data_dir / "vecto-cycles" / "Construction.vdri"
    path = tmp_path / "construction.toml"
    path.write_text(SHORT.split("[route]")[0] + f'[route]\nvdri = "{cycle.as_posix()}"\n')
    scenario = load_scenario(path)
    road = build_road(scenario, 0)
    from haulprofile.analysis.vecto import read_vdri
    vdri = read_vdri(cycle)
    assert road.length_m == pytest.approx(vdri["distance_m"].iloc[-1], abs=1.0)
    assert np.allclose(road.gradient_pct, np.interp(road.distance_m, vdri["distance_m"], vdri["gradient_pct"]))
    stops = vdri[(vdri["target_speed_mps"] == 0) & (vdri["stop_time_s"] > 0) & (vdri["distance_m"] > 0)
                 & (vdri["distance_m"] < road.length_m - 1.0)]
    assert len(road.stop_distance_m) == len(stops) + 1
    states = simulate(scenario, scenario_vehicle(scenario), road)
    limit = np.interp(states["distance_m"], road.distance_m, road.target_speed_mps)
    assert np.all(states["speed_mps"] <= limit + scenario.driver.downhill_overspeed_kmh / 3.6 + 0.3)


@pytest.mark.parametrize("stream, rate_hz", [("wheel_speed", 10), ("engine", 100), ("transmission", 10),
                                             ("pedals", 20), ("fuel", 1), ("weight", 1), ("barometer", 25),
                                             ("humidity", 12.5), ("imu", 238), ("gps", 1)])
def test_sensor_streams_have_their_rates(short_drive, stream, rate_hz):
    time = short_drive.sensors[stream]["time_s"].to_numpy()
    assert np.allclose(np.diff(time), 1 / rate_hz)
    assert time[-1] == pytest.approx(short_drive.states["time_s"].iloc[-1], abs=1 / rate_hz + 1e-9)


def test_sensor_values_have_can_resolution_and_bounded_errors(short_drive):
    sensors, states = short_drive.sensors, short_drive.states
    engine = sensors["engine"]
    assert np.allclose(engine["engine_speed_rpm"] / 0.125, np.round(engine["engine_speed_rpm"] / 0.125))
    assert np.array_equal(engine["actual_engine_torque_pct"], np.round(engine["actual_engine_torque_pct"]))
    kmh = sensors["wheel_speed"]["wheel_speed_kmh"]
    assert np.allclose(kmh * 256, np.round(kmh * 256))
    weight = sensors["weight"]
    mass = np.interp(weight["time_s"], states["time_s"], states["mass_kg"])
    assert np.max(np.abs(weight["gross_combination_weight_kg"] / mass - 1)) < 0.05 + 0.01
    assert np.allclose(weight["gross_combination_weight_kg"] % 10, 0)
    assert sensors["engine_reference_torque_nm"] == short_drive.vehicle.engine_reference_torque_nm
