"""Physics of the longitudinal simulation: energy balance, closed-form road load, stops, speed bound."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import road_load
from haulprofile.analysis.simulate import DriverSettings, distance_cycle, read_cycle, simulate_cycle, time_cycle
from haulprofile.analysis.simulate.cycle import SimulationInputError
from haulprofile.analysis.vehicle import load_vehicle

KMH = 3.6


@pytest.fixture(scope="module")
def rigid():
    return load_vehicle("rigid-18t")


def vdri_frame(rows):
    """(distance_m, speed_kmh, gradient_pct, stop_s) rows as the SI frame `read_vdri` returns."""
    d, v, g, s = (np.asarray(c, float) for c in zip(*rows))
    return pd.DataFrame({"distance_m": d, "target_speed_mps": v / KMH, "gradient_pct": g, "stop_time_s": s})


HILLY_WITH_STOPS = vdri_frame([
    (0, 0, 0.0, 5), (10, 50, 1.5, 0), (800, 80, 4.0, 0), (2500, 80, -5.0, 0), (3800, 60, -2.0, 0),
    (4600, 0, 0.0, 37), (4610, 70, 2.0, 0), (6000, 30, 0.0, 0), (6500, 85, -1.0, 0), (9000, 0, 0.0, 3)])


def energy_balance_terms(result, vehicle):
    """Right-hand side of battery energy = wheel work + losses + auxiliaries, with the road work
    recomputed from the trace through `analysis.road_load` [J]."""
    tr = result.trace
    mass = np.full(len(tr), result.numbers["mean_mass_kg"])
    m_eff = mass + vehicle.electric_powertrain.rotating_mass_kg
    speed_end = np.append(tr["speed_mps"].to_numpy()[1:], 0.0)
    kinetic = np.sum(0.5 * m_eff * (speed_end ** 2 - tr["speed_mps"].to_numpy() ** 2))
    ds = tr["step_distance_m"].to_numpy()
    road = np.sum(road_load.resistance_force_n(tr["speed_mps"], tr["gradient_pct"], mass, vehicle) * ds)
    losses = tr[["friction_brake_energy_j", "gear_loss_j", "machine_loss_j", "inverter_loss_j",
                 "battery_loss_j"]].to_numpy().sum()
    auxiliaries = (tr["auxiliary_energy_j"] + tr["epto_energy_j"] - tr["obc_energy_j"]).sum()
    return kinetic + road + losses + auxiliaries


def test_energy_balance_closes_on_hilly_cycle_with_stops(rigid):
    cycle = distance_cycle(HILLY_WITH_STOPS, 16_000.0, "hilly")
    result = simulate_cycle(cycle, rigid, epto_power_w=(np.array([0.0, 300.0]), np.array([5_000.0, 15_000.0])),
                      obc_power_w=2_000.0)
    battery = result.trace["battery_energy_j"].sum()
    assert battery > 0
    assert energy_balance_terms(result, rigid) == pytest.approx(battery, rel=1e-3)
    assert result.numbers["friction_brake_energy_kwh"] > 0, "the -5 % descent must need the friction brake"


def test_energy_balance_closes_on_vecto_regional_delivery(rigid, data_dir):
    cycle = read_cycle(data_dir / "vecto-cycles" / "RegionalDelivery.vdri", rigid)
    result = simulate_cycle(cycle, rigid)
    battery = result.trace["battery_energy_j"].sum()
    assert energy_balance_terms(result, rigid) == pytest.approx(battery, rel=1e-3)
    soc_drop = result.trace["battery_current_a"].sum() * 0.1 / (350 * 3.6e6 / 650)
    assert result.numbers["final_soc"] == pytest.approx(0.95 - soc_drop, abs=1e-12)


def test_flat_constant_speed_matches_closed_form_road_load(rigid):
    speed, mass = 80 / KMH, 18_000.0
    cycle = distance_cycle(vdri_frame([(0, 80, 0, 0), (20_000, 80, 0, 0)]), mass)
    result = simulate_cycle(cycle, rigid)
    steady = result.trace[result.trace["distance_m"] > 5_000]
    assert np.allclose(steady["speed_mps"], speed, rtol=1e-6)
    force = road_load.resistance_force_n(speed, 0.0, mass, rigid)
    assert np.allclose(steady["traction_force_n"], force, rtol=1e-5)
    ep = rigid.electric_powertrain
    dc_power = force * speed / (rigid.driveline_efficiency * ep.machine_efficiency * ep.inverter_efficiency) \
        + ep.auxiliary_power_w
    current = min(np.roots([ep.battery_internal_resistance_ohm, -ep.battery_voltage_v, dc_power]).real)
    assert np.allclose(steady["battery_terminal_power_w"], dc_power, rtol=1e-5)
    assert np.allclose(steady["battery_current_a"], current, rtol=1e-5)
    wheel_energy = steady["wheel_traction_energy_j"].sum()
    assert wheel_energy == pytest.approx(force * steady["step_distance_m"].sum(), rel=1e-5)


@pytest.mark.parametrize("stop_s", [1.0, 37.0, 120.5])
def test_stop_of_n_seconds_gives_n_seconds_at_standstill(rigid, stop_s):
    frame = vdri_frame([(0, 60, 0, 0), (1500, 0, 0, stop_s), (1510, 60, 0, 0), (3000, 60, 0, 0)])
    result = simulate_cycle(distance_cycle(frame, 15_000.0), rigid)
    tr = result.trace
    standstill = tr[tr["driver_state"] == 0]
    assert len(standstill) * 0.1 == pytest.approx(stop_s, abs=1e-9)
    assert np.allclose(standstill["distance_m"], 1500.0, atol=1e-6)
    assert np.all(standstill["speed_mps"] == 0.0)
    assert tr["distance_m"].iloc[-1] + tr["step_distance_m"].iloc[-1] == pytest.approx(3000.0, abs=60 / KMH * 0.1)


def test_driver_never_exceeds_target_beyond_tolerance(rigid, data_dir):
    settings = DriverSettings()
    cycles = [distance_cycle(HILLY_WITH_STOPS, 26_000.0, "hilly")]
    cycles += [read_cycle(data_dir / "vecto-cycles" / f"{name}.vdri", rigid) for name in ("LongHaul", "Urban")]
    for cycle in cycles:
        result = simulate_cycle(cycle, rigid, settings=settings)
        overspeed = result.trace["speed_mps"] - result.trace["target_speed_mps"]
        assert overspeed.max() <= settings.speed_tolerance_mps, cycle.name


def test_recuperation_limit_and_friction_blending(rigid):
    limit = rigid.electric_powertrain.max_recuperation_power_w
    frame = vdri_frame([(0, 85, 0, 0), (3000, 85, -8, 0), (6000, 85, 0, 0), (6400, 0, 0, 1)])
    result = simulate_cycle(distance_cycle(frame, 26_000.0), rigid)
    tr = result.trace
    shaft_power = tr["machine_torque_nm"] * tr["machine_speed_radps"]
    assert shaft_power.min() >= -limit * 1.01
    assert shaft_power.min() <= -limit * 0.95, "an 8 % descent at 26 t must use the full recuperation"
    braking = tr["friction_brake_force_n"] < -1.0
    assert braking.any() and np.all(shaft_power[braking] <= -limit * 0.9)


def test_machine_limits_are_respected_and_misses_reported(rigid):
    ep = rigid.electric_powertrain
    frame = vdri_frame([(0, 0, 0, 1), (5, 80, 12, 0), (3000, 80, 12, 0)])
    result = simulate_cycle(distance_cycle(frame, 28_000.0), rigid)
    tr = result.trace
    assert np.all(np.abs(tr["machine_torque_nm"]) <= ep.machine_max_torque_nm * (1 + 1e-9))
    assert np.all(tr["machine_torque_nm"] * tr["machine_speed_radps"] <= ep.machine_max_power_w * 1.02)
    climb_speed = tr["speed_mps"].iloc[-100:].mean()
    power_limited_speed = ep.machine_max_power_w * rigid.driveline_efficiency / float(
        road_load.resistance_force_n(climb_speed, 12.0, 28_000.0, rigid))
    assert climb_speed == pytest.approx(power_limited_speed, rel=0.01)
    last = result.misses.iloc[-1]
    assert last["end_distance_m"] == pytest.approx(3000.0, abs=5.0), "the miss lasts to the end of the climb"
    assert last["max_speed_deficit_mps"] >= 80 / KMH - climb_speed - 1e-6


def test_time_based_cycle_is_followed_and_standstill_kept(rigid):
    time = np.arange(0.0, 301.0)
    speed = np.interp(time, [0, 20, 60, 120, 160, 200, 240, 300], [0, 0, 15, 15, 0, 0, 10, 0])
    frame = pd.DataFrame({"time_s": time, "speed_mps": speed, "gradient_pct": 1.0})
    result = simulate_cycle(time_cycle(frame, 15_000.0), rigid)
    tr = result.trace
    assert np.max(np.abs(tr["speed_mps"] - np.interp(tr["time_s"], time, speed))) < 0.05
    standstill = tr[(tr["time_s"] >= 160) & (tr["time_s"] < 200)]
    assert np.all(standstill["speed_mps"] == 0.0)
    assert tr["time_s"].iloc[-1] == pytest.approx(299.9)


def test_constant_efficiency_map_equals_constant_efficiency(rigid, tmp_path):
    ep = rigid.electric_powertrain
    grid = [(n, t, ep.machine_efficiency) for n in (0, 2000, 4000) for t in (0, 1200, 2400)]
    path = tmp_path / "map.csv"
    pd.DataFrame(grid, columns=["speed_rpm", "torque_nm", "efficiency"]).to_csv(path, index=False)
    mapped = dataclasses.replace(rigid, electric_powertrain=dataclasses.replace(ep, efficiency_map_csv=str(path)))
    cycle = distance_cycle(HILLY_WITH_STOPS, 16_000.0)
    a, b = simulate_cycle(cycle, rigid), simulate_cycle(cycle, mapped)
    assert a.numbers["battery_terminal_energy_kwh"] == pytest.approx(b.numbers["battery_terminal_energy_kwh"], rel=1e-9)
    bad = tmp_path / "bad.csv"
    pd.DataFrame({"speed_rpm": [0, 1000], "torque_nm": [0, 10], "efficiency": [0.9, 0.9]}).to_csv(bad, index=False)
    broken = dataclasses.replace(rigid, electric_powertrain=dataclasses.replace(ep, efficiency_map_csv=str(bad)))
    with pytest.raises(SimulationInputError, match="regular"):
        simulate_cycle(cycle, broken)


def test_bad_inputs_are_one_line_user_errors(rigid, tmp_path):
    with pytest.raises(SimulationInputError, match="not found"):
        read_cycle(tmp_path / "missing.vdri", rigid)
    with pytest.raises(SimulationInputError, match="time_s must rise"):
        time_cycle(pd.DataFrame({"time_s": [0.0, 0.0], "speed_mps": [1.0, 2.0]}), 10_000.0)
    no_ep = dataclasses.replace(rigid, electric_powertrain=None)
    with pytest.raises(SimulationInputError, match="electric_powertrain"):
        simulate_cycle(distance_cycle(HILLY_WITH_STOPS, 16_000.0), no_ep)


def test_map_path_is_relative_to_vehicle_file_and_axle_ratio_defaults_to_vehicle(tmp_path, rigid):
    from haulprofile.analysis.vehicle import load_vehicle as load
    (tmp_path / "maps").mkdir()
    grid = [(n, t, 0.9) for n in (0, 4000) for t in (0, 2400)]
    pd.DataFrame(grid, columns=["speed_rpm", "torque_nm", "efficiency"]).to_csv(tmp_path / "maps" / "em.csv", index=False)
    text = """[vehicle]
name = "test"
curb_mass_kg = 9000
drag_coefficient = 0.6
frontal_area_m2 = 8.9
rolling_resistance_coefficient = 0.0065
wheel_radius_m = 0.492
driveline_efficiency = 0.93
gear_ratios = [1.0]
axle_ratio = 3.07

[electric_powertrain]
machine_max_torque_nm = 2400
machine_max_power_w = 350000
machine_max_speed_rpm = 4000
battery_capacity_kwh = 350
battery_voltage_v = 650
efficiency_map_csv = "maps/em.csv"
gear_ratios = [3.2, 1.0]
"""
    (tmp_path / "truck.toml").write_text(text)
    mapped = load(tmp_path / "truck.toml")
    explicit = dataclasses.replace(mapped, electric_powertrain=dataclasses.replace(
        mapped.electric_powertrain, efficiency_map_csv=None, machine_efficiency=0.9, axle_ratio=3.07))
    cycle = distance_cycle(HILLY_WITH_STOPS, 16_000.0)
    a, b = simulate_cycle(cycle, mapped), simulate_cycle(cycle, explicit)
    assert a.numbers["battery_terminal_energy_kwh"] == pytest.approx(b.numbers["battery_terminal_energy_kwh"], rel=1e-9)


def test_driver_holds_the_target_until_a_far_lower_target_is_near(rigid):
    """A lower limit 3 km ahead, with small target wiggles on the way: the driver keeps 80 km/h and
    coasts down only in the last few hundred metres, not from the first moment it sees the limit."""
    rows = [(0, 80, 0, 0)] + [(200 + 100 * i, 80 - (i % 2), 0, 0) for i in range(28)] + [(3000, 50, 0, 0),
                                                                                        (5000, 50, 0, 0)]
    tr = simulate_cycle(distance_cycle(vdri_frame(rows), 16_000.0), rigid).trace
    cruise = tr[(tr["distance_m"] > 1000) & (tr["distance_m"] < 2000)]
    assert (cruise["target_speed_mps"] - cruise["speed_mps"]).max() < 1.0
    assert tr.loc[(tr["distance_m"] > 2990) & (tr["distance_m"] < 3010), "speed_mps"].max() < 52 / KMH
