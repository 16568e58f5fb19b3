"""The accessories' torque (J1939 EEC3 SPN 2978): the virtual truck sends what its engine controller
estimates, the ingest decodes it, and the mass and the force balance take it off the reported torque
where it is reported and changes."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.engine_torque import REPORTED, SUBTRACTED, driveline_torque_nm, parasitic_torque_nm
from haulprofile.analysis.errors import UserError
from haulprofile.analysis.ingest import read_logs
from haulprofile.analysis.mass import estimate_mass
from haulprofile.analysis.mass.regression import build_regression
from haulprofile.analysis.virtual_truck import drive, realism_level, write_mcap
from haulprofile.analysis.virtual_truck.driver import drag_torque_nm
from haulprofile.testing.accuracy import Case, analysed_to_gradient, case_scenario

CLEAN = dict(torque_gain_pct=0.0, torque_offset_pct=0.0, driveline_gear_spread=0.0, driveline_spin_loss_pct=0.0,
             wind_mps=0.0, wind_gust_mps=0.0, aux_compressor_kw=15.0, aux_fan_kw=30.0)
"""A typical drive whose torque report and driveline have no error but the accessories, which are large."""


def _urban(**sizes):
    return drive(case_scenario(Case("urban-delivery", "typical", 1, 8000.0)), seed=1,
                 realism=realism_level("typical", **sizes))


@pytest.fixture(scope="module")
def exact():
    return _urban(**CLEAN, parasitic_estimate_error_pct=0.0)


@pytest.fixture(scope="module")
def logged(exact, tmp_path_factory):
    """The signals table of ``exact`` with the gradient columns (the pipeline up to the gradient)."""
    return analysed_to_gradient(exact, tmp_path_factory.mktemp("eec3")).signals


def test_eec3_sends_the_engines_friction_and_its_estimate_of_the_accessories(exact):
    sent = exact.sensors["engine_losses"]
    assert np.allclose(np.diff(sent["time_s"]), 0.25)
    states, vehicle = exact.states, exact.vehicle
    ref = vehicle.engine_reference_torque_nm
    index = np.searchsorted(states["time_s"].to_numpy(), sent["time_s"].to_numpy(), side="right") - 1
    rpm = states["engine_speed_rpm"].to_numpy()[index]
    drag = np.array([drag_torque_nm(r, ref, vehicle.engine.idle_speed_rpm, vehicle.engine.max_speed_rpm) for r in rpm])
    assert np.array_equal(sent["nominal_friction_torque_pct"], np.round(-drag / ref * 100))
    accessories = (states["aux_compressor_torque_nm"] + states["aux_fan_torque_nm"]).to_numpy()[index]
    assert np.max(np.abs(sent["parasitic_loss_torque_pct"] - accessories / ref * 100)) <= 0.5 + 1e-9
    assert sent["parasitic_loss_torque_pct"].max() >= 3 and (sent["parasitic_loss_torque_pct"] == 0).mean() > 0.5


def test_the_estimates_error_is_per_drive_and_per_consumer():
    drawn = _urban(**CLEAN).injected
    assert drawn["parasitic_compressor_gain"] != drawn["parasitic_fan_gain"]
    for key in ("parasitic_compressor_gain", "parasitic_fan_gain"):
        assert abs(drawn[key] - 1) <= 0.15


def test_a_truck_that_does_not_report_it_sends_not_available_and_nothing_else_changes(exact, tmp_path):
    silent = _urban(**CLEAN, parasitic_estimate_error_pct=0.0, parasitic_report="not available")
    assert silent.sensors["engine_losses"]["parasitic_loss_torque_pct"].isna().all()
    for name in ("engine", "wheel_speed", "imu", "gps", "barometer"):
        assert silent.sensors[name].equals(exact.sensors[name]), name
    table = read_logs([write_mcap(silent, tmp_path / "silent.mcap")])
    assert "engine_parasitic_torque_nm" not in table.columns and table["engine_friction_torque_nm"].notna().all()
    zero = _urban(**CLEAN, parasitic_report="zero")
    assert (zero.sensors["engine_losses"]["parasitic_loss_torque_pct"] == 0).all()
    with pytest.raises(UserError, match="parasitic_report: expected one of"):
        realism_level("typical", parasitic_report="sometimes")


def test_the_ingest_gives_back_what_eec3_sent(exact, logged):
    ref = exact.vehicle.engine_reference_torque_nm
    sent = exact.sensors["engine_losses"]
    for column, spn in (("engine_parasitic_torque_nm", "parasitic_loss_torque_pct"),
                        ("engine_friction_torque_nm", "nominal_friction_torque_pct")):
        values = logged[column].to_numpy()
        assert set(np.unique(values[np.isfinite(values)])) <= set(np.unique(sent[spn]) / 100 * ref)
        assert np.mean(values) == pytest.approx(np.mean(sent[spn]) / 100 * ref, rel=0.02)


def test_the_mass_regresses_on_the_torque_that_reaches_the_driveline(exact, logged):
    """With the accessories reported the force the mass is fitted on is the truth's wheel force;
    without, it is the accessories' share too high."""
    frame = logged.assign(gradient_pct=logged["gradient_smooth_pct"])
    truth = exact.states
    wheel = np.interp(frame["time_s"], truth["time_s"], truth["wheel_force_n"])
    accessories = np.interp(frame["time_s"], truth["time_s"], truth["aux_torque_nm"])
    errors = {}
    for name, table in (("subtracted", frame), ("reported", frame.drop(columns="engine_parasitic_torque_nm"))):
        regression = build_regression(table, exact.vehicle)
        loaded = regression.usable & (accessories > 50)
        errors[name] = np.mean(regression.force[loaded]) / np.mean(wheel[loaded]) - 1
    assert abs(errors["subtracted"]) < 0.01
    assert errors["reported"] > 0.1
    assert estimate_mass(frame, exact.vehicle).summary()["engine_torque"] == SUBTRACTED
    assert estimate_mass(frame.drop(columns="engine_parasitic_torque_nm"), exact.vehicle).engine_torque == REPORTED


def test_the_force_balance_reads_the_torque_that_reaches_the_driveline(exact, logged):
    """The gradient's virtual accelerometer with the true mass: a + g sin(alpha) where the
    accessories run, within 0.02 m/s² with them taken off, not without."""
    from haulprofile.analysis.gradient.force_balance import virtual_accelerometer_mps2
    truth = exact.states
    time_s = logged["time_s"]
    mass = np.interp(time_s, truth["time_s"], truth["mass_kg"])
    angle = np.arctan(np.interp(time_s, truth["time_s"], truth["gradient_pct"]) / 100)
    true = np.interp(time_s, truth["time_s"], truth["accel_mps2"]) + 9.80665 * np.sin(angle)
    loaded = np.interp(time_s, truth["time_s"], truth["aux_torque_nm"]) > 50
    bias = {}
    for name, table in (("subtracted", logged), ("reported", logged.drop(columns="engine_parasitic_torque_nm"))):
        virtual = virtual_accelerometer_mps2(table, exact.vehicle, mass)
        keep = loaded & np.isfinite(virtual)
        bias[name] = np.mean(virtual[keep] - true[keep])
    assert abs(bias["subtracted"]) < 0.02 < bias["reported"]


def test_a_missing_or_constant_parasitic_torque_leaves_the_reported_torque():
    frame = pd.DataFrame({"engine_torque_nm": [500.0, 800.0, 900.0, 1000.0]})
    assert parasitic_torque_nm(frame) is None
    for constant in (0.0, 52.0, np.nan):
        assert np.array_equal(driveline_torque_nm(frame.assign(engine_parasitic_torque_nm=constant)),
                              frame["engine_torque_nm"].to_numpy())
    moving = frame.assign(engine_parasitic_torque_nm=[0.0, 50.0, np.nan, 26.0])
    assert np.array_equal(driveline_torque_nm(moving), [500.0, 750.0, 900.0, 974.0])
