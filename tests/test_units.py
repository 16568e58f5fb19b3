"""Units leave the program with every table: Parquet field metadata, a CSV's units sidecar, DBC
units for DBC signals."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from haulprofile.analysis import cli
from haulprofile.analysis.signals import read_signals, write_signals
from haulprofile.analysis.units import parquet_units, sidecar, unit_of


def test_names_give_their_units():
    assert unit_of("speed_mps") == "m/s"
    assert unit_of("accel_mps2") == "m/s²"
    assert unit_of("engine_torque_nm") == "Nm"
    assert unit_of("wall_time_ns") == "ns"
    assert unit_of("air_temperature_c") == "°C"
    assert unit_of("valid") == "" and unit_of("EngineSpeed") == ""
    assert unit_of("EngineSpeed", {"EngineSpeed": "rpm"}) == "rpm"


def test_dbc_units_reach_the_parquet_field_metadata(tmp_path, data_dir):
    out = tmp_path / "signals.parquet"
    log = data_dir / "real-can" / "css-j1939-idle-127s.MF4"
    dbc = data_dir / "real-can" / "CSS-Electronics-SAE-J1939-DEMO.dbc"
    assert cli.main(["signals", str(log), "--dbc", str(dbc), "-o", str(out), "--quiet"]) == 0
    fields = {f.name: f for f in pq.read_schema(out)}
    assert fields["EngineSpeed"].metadata[b"unit"] == b"rpm"
    assert fields["speed_mps"].metadata[b"unit"] == b"m/s"
    assert parquet_units(out)["engine_speed_rpm"] == "rpm"
    assert read_signals(out).attrs["units"]["EngineSpeed"] == "rpm"


def test_csv_tables_carry_a_units_sidecar(tmp_path):
    frame = pd.DataFrame({"time_s": np.arange(3) * 0.1, "speed_mps": [0.0, 1.0, 2.0], "Oil": [1.0, 2.0, 3.0]})
    frame.attrs["units"] = {"Oil": "bar"}
    path = write_signals(frame, tmp_path / "drive.csv")
    assert sidecar(path).name == "drive.csv.units.json"
    units = json.loads(sidecar(path).read_text(encoding="utf-8"))
    assert units == {"time_s": "s", "speed_mps": "m/s", "Oil": "bar"}
    assert pd.read_csv(path).columns.tolist() == ["time_s", "speed_mps", "Oil"]  # one header row, as before
    assert read_signals(path).attrs["units"] == {"Oil": "bar"}
