"""The accessories' torque (J1939 EEC3 SPN 2978): the virtual truck sends what its engine controller
estimates, and the ingest decodes it."""

from __future__ import annotations

import numpy as np
import pytest

from haulprofile.analysis.errors import UserError
from haulprofile.analysis.ingest import read_logs
from haulprofile.analysis.virtual_truck import drive, realism_level, write_dem, write_mcap
from haulprofile.analysis.virtual_truck.driver import drag_torque_nm
from haulprofile.testing.accuracy import Case, case_scenario

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
    from haulprofile.analysis.pipeline import RunContext, run
    root = tmp_path_factory.mktemp("eec3")
    write_dem(exact, root / "dem")
    write_mcap(exact, root / "logs" / "drive.mcap")
    ctx = RunContext(inputs=[root / "logs"], out_dir=root / "out", vehicle=exact.vehicle, dem_dir=root / "dem",
                     say=lambda _m: None, options={"output": {"figures": False}})
    run(ctx, until="gradient")
    return ctx.signals


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
