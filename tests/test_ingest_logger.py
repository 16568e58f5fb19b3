"""The logger daemon (emulated devices, real daemon and storage) → MCAP → ingest."""

import numpy as np
import pytest

from haulprofile.analysis.ingest import ingest_logs
from haulprofile.contract import j1939

REFERENCE_NM = 2000.0


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from haulprofile.logger.emulators import record_drive

    t = np.arange(0, 12, 0.01)
    signals = {"time_s": t, "speed_mps": 10 + 5 * np.sin(t / 3), "engine_speed_rpm": 1200 + 100 * np.sin(t),
               "actual_engine_torque_pct": 40 + 10 * np.sin(t / 2), "driver_demand_torque_pct": 45 + 0 * t,
               "engine_reference_torque_nm": REFERENCE_NM + 0 * t, "pressure_pa": 98000 + 10 * t,
               "temperature_c": 15 + 0 * t, "relative_humidity_pct": 50 + 0 * t, "accel_x_mps2": 0.3 + 0 * t,
               "accel_y_mps2": 0 * t, "accel_z_mps2": 9.81 + 0 * t, "latitude_deg": 50 + t * 1e-5,
               "longitude_deg": 6 + 0 * t, "altitude_m": 200 + 0 * t, "h_acc_m": 1 + 0 * t, "v_acc_m": 2 + 0 * t}
    path = record_drive(signals, tmp_path_factory.mktemp("daemon"), time_scale=4.0)
    return signals, ingest_logs([path])


def test_daemon_log_decodes_into_the_driven_ranges(recorded):
    signals, (frame, summary) = recorded
    assert summary["warnings"] == [] and summary["files"][0]["complete"]
    assert summary["transport_protocol"]["bam"] >= 1
    assert (frame["engine_reference_torque_nm"].dropna() == REFERENCE_NM).all()
    speed_q = j1939.SPNS["wheel_speed_kmh"].resolution / 3.6
    speed = frame["speed_mps"].dropna()
    assert len(speed) > 0.8 * len(frame)
    assert speed.min() >= 5 - speed_q and speed.max() <= 15 + speed_q
    torque = frame["engine_torque_nm"].dropna()
    assert torque.min() >= 0.295 * REFERENCE_NM and torque.max() <= 0.505 * REFERENCE_NM
    assert frame["engine_speed_rpm"].dropna().between(1100 - 0.125, 1300 + 0.125).all()
    assert frame["pressure_pa"].dropna().between(97_990, 98_130).all()
    assert frame["accel_x_mps2"].dropna().sub(0.3).abs().max() < 0.01
    assert frame["latitude_deg"].dropna().between(50 - 1e-9, 50 + 12.1e-5).all()
    assert summary["sources"]["speed_mps"]["source"] == "j1939"
