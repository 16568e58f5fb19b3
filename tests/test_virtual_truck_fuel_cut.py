"""The virtual truck's accessories and driveline losses where the engine is motored: in a fuel cut
the engine burns nothing, its net torque is its friction, and the wheels drive the compressor, the
fan and the driveline's spin loss, so the truck slows by all of them; the torque report says
-friction (net) or 0 % (indicated) and EEC3 still says what the accessories take. Where the engine
burns fuel it makes them, up to its full-load torque."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from haulprofile.analysis import road_load
from haulprofile.analysis.engine_torque import driveline_torque_nm
from haulprofile.analysis.ingest import read_logs
from haulprofile.analysis.virtual_truck import drive, load_scenario, realism_level, write_mcap
from haulprofile.analysis.virtual_truck.disturbances import Accessories
from haulprofile.analysis.virtual_truck.driver import friction_torque_nm, gearbox_torque_nm, simulate_kernel
from haulprofile.analysis.virtual_truck.truck import scenario_vehicle, simulate
from haulprofile.analysis.virtual_truck.world import build_road
from haulprofile.testing.accuracy import Case, case_scenario
from test_virtual_truck import SHORT

CLEAN = dict(torque_gain_pct=0.0, torque_offset_pct=0.0, driveline_gear_spread=0.0, driveline_spin_loss_pct=0.0,
             wind_mps=0.0, wind_gust_mps=0.0, aux_compressor_kw=15.0, aux_fan_kw=30.0, parasitic_estimate_error_pct=0.0)
"""A typical drive with a nominal driveline, no wind and no error in the torque report, but large
accessories whose torque the engine controller knows exactly."""


def _urban(level="typical", **sizes):
    scenario = case_scenario(Case("urban-delivery", level, 1, 8000.0))
    scenario = dataclasses.replace(scenario, sensors=dataclasses.replace(scenario.sensors, engine_torque_noise_pct=0.0))
    return drive(scenario, seed=1, realism=realism_level(level, **sizes))


@pytest.fixture(scope="module")
def clean():
    return _urban(**CLEAN)


def _held(states, column, time_s):
    index = np.searchsorted(states["time_s"].to_numpy(), time_s, side="right") - 1
    return states[column].to_numpy()[np.clip(index, 0, len(states) - 1)]


def _coasting_in_a_fuel_cut(states):
    """Samples where the engine, in gear with its clutch closed and no brake, is motored by the wheels."""
    return (states["fuel_cut"] & (states["gear"] > 0) & ~states["shifting"] & ~states["clutch_slip"]
            & ~states["brake_active"] & (states["speed_mps"] > 1.0)).to_numpy()


def test_in_a_fuel_cut_the_wheels_drive_the_friction_and_the_accessories(clean):
    states, vehicle = clean.states, clean.vehicle
    cut = _coasting_in_a_fuel_cut(states) & (states["aux_compressor_torque_nm"] > 0).to_numpy()
    assert cut.sum() >= 100
    rpm = states["engine_speed_rpm"].to_numpy()[cut]
    accessories = (states["aux_compressor_torque_nm"] + states["aux_fan_torque_nm"]).to_numpy()[cut]
    ratio = np.asarray(vehicle.total_ratios)[states["gear"].to_numpy()[cut] - 1]
    wheel_torque = -(friction_torque_nm(rpm, vehicle) + accessories) * ratio * vehicle.driveline_efficiency
    force = wheel_torque / vehicle.wheel_radius_m
    np.testing.assert_allclose(states["wheel_force_n"].to_numpy()[cut], force, rtol=1e-9)
    speed, gradient, mass = (states[c].to_numpy()[cut] for c in ("speed_mps", "gradient_pct", "mass_kg"))
    expected = (force - road_load.resistance_force_n(speed, gradient, mass, vehicle)) / mass
    np.testing.assert_allclose(states["accel_mps2"].to_numpy()[cut], expected, rtol=1e-9, atol=1e-12)
    assert np.min(accessories / friction_torque_nm(rpm, vehicle)) > 0.5, "what the test tells apart is large"


def test_over_the_drive_the_energy_of_the_fuel_cuts_comes_from_the_wheels(clean):
    """Σ F v dt over the coasting fuel cuts is what the engine's friction and the accessories
    took, through the driveline: -eta Σ (friction + accessories) omega dt."""
    states, vehicle = clean.states, clean.vehicle
    cut = _coasting_in_a_fuel_cut(states)
    dt_s = states["time_s"].iloc[1] - states["time_s"].iloc[0]
    rpm = states["engine_speed_rpm"].to_numpy()[cut]
    omega = rpm * np.pi / 30
    friction_j = np.sum(friction_torque_nm(rpm, vehicle) * omega) * dt_s
    accessories_j = np.sum(states["aux_torque_nm"].to_numpy()[cut] * omega) * dt_s
    wheel_j = np.sum(states["wheel_force_n"].to_numpy()[cut] * states["speed_mps"].to_numpy()[cut]) * dt_s
    assert wheel_j == pytest.approx(-vehicle.driveline_efficiency * (friction_j + accessories_j), rel=1e-9)
    assert accessories_j > 0.05 * friction_j


def test_the_engine_reports_minus_its_friction_in_a_fuel_cut_and_eec3_the_accessories(clean):
    states, vehicle = clean.states, clean.vehicle
    ref = vehicle.engine_reference_torque_nm
    sent = clean.sensors["engine"]
    t = sent["time_s"].to_numpy()
    cut = _held(states, "fuel_cut", t) & (_held(states, "aux_torque_nm", t) > 0)
    assert cut.sum() >= 100
    friction_pct = np.round(friction_torque_nm(_held(states, "engine_speed_rpm", t[cut]), vehicle) / ref * 100)
    assert np.array_equal(sent["actual_engine_torque_pct"].to_numpy()[cut], -friction_pct)
    assert np.array_equal(states["engine_torque_nm"].to_numpy()[states["fuel_cut"].to_numpy()],
                          -friction_torque_nm(states["engine_speed_rpm"].to_numpy()[states["fuel_cut"].to_numpy()],
                                              vehicle))
    losses = clean.sensors["engine_losses"]
    at = losses["time_s"].to_numpy()
    cut = _held(states, "fuel_cut", at)
    accessories = _held(states, "aux_compressor_torque_nm", at) + _held(states, "aux_fan_torque_nm", at)
    assert np.array_equal(losses["parasitic_loss_torque_pct"].to_numpy()[cut], np.round(accessories[cut] / ref * 100))
    assert (losses["parasitic_loss_torque_pct"].to_numpy()[cut] >= 5).sum() >= 20
    indicated = _urban(**CLEAN, torque_report="indicated").sensors["engine"]
    assert (indicated["actual_engine_torque_pct"].to_numpy()[_held(states, "fuel_cut", t)] == 0).all()


@pytest.mark.parametrize("form", ["net", "indicated"])
def test_the_log_gives_the_torque_the_wheels_drive_in_a_fuel_cut_in_either_form(form, tmp_path):
    """The analysis's driveline torque (report, less SPN 514 if indicated, less SPN 2978) in fuel
    cuts is what the gearbox passed: -(friction + accessories), to the reports' 1 % rounding."""
    virtual = _urban(**CLEAN, torque_report=form)
    table = read_logs([write_mcap(virtual, tmp_path / f"{form}.mcap")])
    states, ref = virtual.states, virtual.vehicle.engine_reference_torque_nm
    t = table["time_s"].to_numpy()
    steady = np.ones(t.shape, bool)
    for shift_s in (-0.5, -0.25, 0.0, 0.25):
        steady &= _held(states, "fuel_cut", t + shift_s)
        steady &= _held(states, "aux_compressor_torque_nm", t + shift_s) == _held(states, "aux_compressor_torque_nm", t)
    steady &= np.isfinite(table["engine_torque_nm"].to_numpy())
    assert steady.sum() >= 100
    residual = driveline_torque_nm(table)[steady] - _held(states, "wheel_engine_torque_nm", t[steady])
    assert np.median(np.abs(residual)) <= 0.01 * ref and np.percentile(np.abs(residual), 95) <= 0.02 * ref


def test_at_full_load_the_wheels_get_what_the_accessories_leave():
    """The engine never delivers more than its full-load torque; at full load with the fan and
    compressor on, the gearbox gets that less what they take (the 40 t tractor on its grades)."""
    states = drive(case_scenario(Case("long-haul", "typical", 1, 8000.0)), seed=1,
                   realism=realism_level("typical", **CLEAN)).states
    engaged = (states["gear"] > 0).to_numpy()
    engine, full = states["engine_torque_nm"].to_numpy(), states["full_load_torque_nm"].to_numpy()
    assert np.max(engine[engaged] - full[engaged]) <= 1e-6
    at_full = engaged & (engine >= full - 1e-6) & (states["aux_torque_nm"].to_numpy() > 0)
    assert at_full.sum() >= 1000
    np.testing.assert_allclose(states["wheel_engine_torque_nm"].to_numpy()[at_full],
                               full[at_full] - states["aux_torque_nm"].to_numpy()[at_full], rtol=1e-9)


def test_with_the_driveline_losses_the_engine_in_a_fuel_cut_still_gives_its_friction_alone():
    """The typical level's gear efficiency and spin loss: the wheels drive them too."""
    virtual = _urban(driveline_gear_spread=0.02, driveline_spin_loss_pct=1.0, aux_compressor_kw=15.0)
    states, vehicle = virtual.states, virtual.vehicle
    cut = _coasting_in_a_fuel_cut(states)
    assert cut.sum() >= 100
    rpm = states["engine_speed_rpm"].to_numpy()[cut]
    np.testing.assert_array_equal(states["engine_torque_nm"].to_numpy()[cut], -friction_torque_nm(rpm, vehicle))
    eta = vehicle.driveline_efficiency
    ratio = np.asarray(vehicle.total_ratios)[states["gear"].to_numpy()[cut] - 1]
    engine_side = (states["engine_torque_nm"] - states["aux_torque_nm"]).to_numpy()[cut] - virtual.injected[
        "driveline_spin_loss_nm"]
    nominal_over_gear = eta / states["driveline_efficiency"].to_numpy()[cut]
    gearbox = np.array([gearbox_torque_nm(x, f) for x, f in zip(engine_side, nominal_over_gear)])
    np.testing.assert_allclose(states["wheel_force_n"].to_numpy()[cut],
                               eta * ratio * gearbox / vehicle.wheel_radius_m, rtol=1e-9)


def test_the_kernel_with_accessories_matches_its_reference(tmp_path):
    path = tmp_path / "short.toml"
    path.write_text(SHORT)
    scenario = load_scenario(path)
    vehicle = scenario_vehicle(scenario)
    road = build_road(scenario, 2, realism_level("typical"))
    steps = 120_000
    on = (np.arange(steps) // 3000) % 2 == 1
    top = len(vehicle.total_ratios)
    accessories = Accessories(on * 12_000.0, ~on * 25_000.0,
                              vehicle.driveline_efficiency + 0.02 * (np.arange(top) / (top - 1) - 0.5), 20.0)
    compiled = simulate(scenario, vehicle, road, accessories=accessories)
    reference = simulate(scenario, vehicle, road, kernel=simulate_kernel.py_func, accessories=accessories)
    for column in compiled.columns:
        assert np.allclose(compiled[column].to_numpy(float), reference[column].to_numpy(float),
                           rtol=1e-9, atol=1e-6), column
    calm = simulate(scenario, vehicle, road)
    n = min(len(compiled), len(calm))
    assert compiled["fuel_cut"].any() and not np.array_equal(compiled["speed_mps"][:n], calm["speed_mps"][:n])
