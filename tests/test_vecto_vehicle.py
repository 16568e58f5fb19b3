"""VECTO's generic vehicles (real files from CLIMA-VECTO/vecto-sim) read into our vehicle file."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from haulprofile.analysis import cli
from haulprofile.analysis.errors import UserError
from haulprofile.analysis.vecto_vehicle import vehicle_tables, vehicle_toml
from haulprofile.analysis.vehicle import load_vehicle, vehicle_from_dict


@pytest.fixture(scope="module")
def vehicles(data_dir):
    return data_dir / "vecto-vehicles"


def test_the_40t_long_haul_job(vehicles):
    truck = load_vehicle(vehicles / "40t-Long-Haul-Truck" / "40t_Long_Haul_Truck.vecto")
    assert truck.curb_mass_kg == 7100.0 and truck.max_payload_kg == 40_000.0 - 7100.0
    assert truck.drag_coefficient * truck.frontal_area_m2 == pytest.approx(6.2985)  # VECTO's CdA
    assert truck.wheel_radius_m == pytest.approx(0.4882675)
    assert truck.axle_ratio == 2.59 and truck.gear_ratios[0] == 14.93 and truck.gear_ratios[-1] == 1.0
    assert len(truck.gear_ratios) == 12
    assert truck.rolling_resistance_coefficient == pytest.approx((0.00555 + 0.00628) / 2)
    assert truck.engine.idle_speed_rpm == 560.0 and truck.engine_reference_torque_nm == 2300.0
    assert truck.engine.max_speed_rpm == 2100.0


def test_vecto_rolling_resistance_with_axle_weight_shares(vehicles):
    """The engineering-mode coach gives its shares: VECTO's RRC = Σ s·RRC·(F_z/FzISO)^(β−1), β 0.9."""
    coach = load_vehicle(vehicles / "24t-Coach" / "24t Coach.vecto")
    mass = 15700.0 + 3300.0
    shares, rrc, fz = np.array([0.4375, 0.375, 0.1875]), np.array([0.0055, 0.0065, 0.0055]), \
        np.array([62538.75, 52532.55, 62538.75])
    expected = float(np.sum(shares * rrc * (shares * mass * 9.81 / fz) ** -0.1))
    assert coach.rolling_resistance_coefficient == pytest.approx(expected, rel=1e-12)
    assert coach.rolling_resistance_coefficient == pytest.approx(0.0058051, abs=1e-7)
    assert coach.wheel_radius_m == 0.52 and coach.max_payload_kg == 24_000.0 - 15700.0


def test_a_vehicle_file_alone_and_the_notes(vehicles):
    tables, notes = vehicle_tables(vehicles / "12t-Delivery-Truck" / "12t Delivery Truck.vveh")
    assert "gear_ratios" not in tables["vehicle"] and "engine" not in tables  # the job names those files
    assert any("declaration-mode" in n for n in notes) and any("c_d·A" in n for n in notes)
    truck = vehicle_from_dict(tables)
    assert truck.curb_mass_kg == 5850.0 and truck.max_payload_kg == pytest.approx(11_900.0 - 5850.0)


def test_analyze_vehicle_writes_a_vehicle_file_that_loads(tmp_path, vehicles, capsys):
    out = tmp_path / "truck.toml"
    job = vehicles / "40t-Long-Haul-Truck" / "40t_Long_Haul_Truck.vecto"
    assert cli.main(["vehicle", str(job), "-o", str(out)]) == 0
    text = out.read_text()
    assert text.startswith("# Converted from the VECTO file") and "declaration-mode" in text
    assert load_vehicle(out) == load_vehicle(job)
    assert tomllib.loads(vehicle_toml(job))["vehicle"]["axle_ratio"] == 2.59
    assert cli.main(["vehicle", str(job), "-o", str(out)]) == 2
    assert "exists" in capsys.readouterr().err


def test_bad_vecto_files_are_one_line(tmp_path):
    broken = tmp_path / "truck.vveh"
    broken.write_text('{"Header": {}, "Body": {"CurbWeight": "heavy"}}')
    with pytest.raises(UserError, match="CurbWeight"):
        load_vehicle(broken)
    with pytest.raises(UserError, match="not found"):
        load_vehicle(tmp_path / "missing.vecto")
