"""J1939's torque report in both forms: SPN 513 net of the engine's friction (negative in a fuel
cut) or as J1939-71 defines it, the indicated torque (friction included, 0 % in a fuel cut, the
friction in EEC3 SPN 514). The analysis tells them apart from the drive and takes the friction off
an indicated report, so the mass does not depend on how the engine reports."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.engine_torque import (FRICTION_SUBTRACTED, INDICATED, NET, NO_FRICTION, UNKNOWN,
                                                driveline_torque_nm, knows_engine_drag, torque_report_form,
                                                torque_used)
from haulprofile.analysis.errors import UserError
from haulprofile.analysis.virtual_truck import drive, realism_level
from haulprofile.testing.accuracy import Case, analysed_to_gradient, case_scenario, mass_errors

CLEAN = dict(torque_gain_pct=0.0, torque_offset_pct=0.0, driveline_gear_spread=0.0, driveline_spin_loss_pct=0.0,
             wind_mps=0.0, wind_gust_mps=0.0)


def _urban(**sizes):
    return drive(case_scenario(Case("urban-delivery", "typical", 1, 8000.0)), seed=1,
                 realism=realism_level("typical", **CLEAN, **sizes))


def _frame(torque_nm, speed_mps, friction_nm=None, dt_s=0.1):
    frame = pd.DataFrame({"time_s": np.arange(len(torque_nm)) * dt_s, "engine_torque_nm": torque_nm,
                          "speed_mps": speed_mps})
    return frame if friction_nm is None else frame.assign(engine_friction_torque_nm=friction_nm)


def _drive_with(coast_nm, idle_nm, coast_s=120.0):
    """60 s idling, 300 s pulling, a coast of ``coast_s`` at ``coast_nm``, 300 s pulling; 100 Nm of
    friction throughout."""
    n_coast = int(coast_s * 10)
    torque = np.concatenate([np.full(600, idle_nm), np.full(3000, 900.0), np.full(n_coast, coast_nm),
                             np.full(3000, 900.0)])
    speed = np.concatenate([np.zeros(600), np.full(6000 + n_coast, 15.0)])
    return _frame(torque, speed, np.full(torque.size, 100.0))


def test_the_form_is_told_by_what_the_report_does_in_a_fuel_cut():
    assert torque_report_form(_drive_with(coast_nm=-100.0, idle_nm=30.0)) == NET
    indicated = _drive_with(coast_nm=0.0, idle_nm=130.0)
    assert torque_report_form(indicated) == INDICATED
    assert np.array_equal(driveline_torque_nm(indicated), indicated["engine_torque_nm"] - 100.0)
    assert knows_engine_drag(indicated) and torque_used(indicated).startswith(FRICTION_SUBTRACTED)


def test_zeros_that_cannot_be_an_indicated_torque_leave_the_report_as_it_is():
    short = _drive_with(coast_nm=0.0, idle_nm=130.0, coast_s=1.0)
    assert torque_report_form(short) == UNKNOWN, "a gear shift's unloaded engine, not a fuel cut"
    standing = _frame(np.full(100, 130.0), np.zeros(100), np.full(100, 100.0))
    assert torque_report_form(standing) == UNKNOWN
    for frame in (short, standing):
        assert np.array_equal(driveline_torque_nm(frame), frame["engine_torque_nm"].to_numpy())


def test_an_indicated_report_without_the_friction_is_said_and_not_corrected():
    frame = _drive_with(coast_nm=0.0, idle_nm=130.0).drop(columns="engine_friction_torque_nm")
    assert torque_report_form(frame) == INDICATED and not knows_engine_drag(frame)
    assert np.array_equal(driveline_torque_nm(frame), frame["engine_torque_nm"].to_numpy())
    assert torque_used(frame).startswith(NO_FRICTION)


def test_the_virtual_truck_sends_the_indicated_form_with_its_friction():
    net, indicated = _urban(), _urban(torque_report="indicated")
    assert net.injected.get("torque_report") is None and indicated.injected["torque_report"] == "indicated"
    sent_net, sent = net.sensors["engine"], indicated.sensors["engine"]
    assert (sent_net["actual_engine_torque_pct"] < 0).mean() > 0.05
    assert sent["actual_engine_torque_pct"].min() == 0 and (sent["actual_engine_torque_pct"] == 0).mean() > 0.05
    added = sent["actual_engine_torque_pct"] - sent_net["actual_engine_torque_pct"]
    assert added[sent["actual_engine_torque_pct"] > 0].between(3, 8).all(), "3 % of the reference at idle to 8 %"
    for name in ("engine_losses", "wheel_speed", "transmission"):
        assert indicated.sensors[name].equals(net.sensors[name]), name
    with pytest.raises(UserError, match="torque_report: expected one of"):
        realism_level("typical", torque_report="gross")


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """Signals tables (up to the gradient) of one drive whose engine reports net and indicated."""
    tables = {}
    for form in ("net", "indicated"):
        virtual = _urban(torque_report=form)
        tables[form] = (virtual, analysed_to_gradient(virtual, tmp_path_factory.mktemp(form)).signals)
    return tables


def test_the_mass_does_not_depend_on_the_form_of_the_report(logged):
    """Each segment's joint mass against the truth, from the same drive reported in both forms."""
    (virtual, net), (_, indicated) = logged["net"], logged["indicated"]
    assert torque_report_form(net) == NET and torque_report_form(indicated) == INDICATED
    errors = {form: mass_errors(frame, virtual.truth, virtual.vehicle, "gradient_smooth_pct")["mass_kg"]
              for form, frame in (("net", net), ("indicated", indicated))}
    assert len(errors["net"]) >= 2 and len(errors["indicated"]) == len(errors["net"])
    np.testing.assert_allclose(errors["indicated"], errors["net"], atol=0.01)
    assert np.max(np.abs(errors["net"])) < 0.05
