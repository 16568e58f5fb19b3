"""``analyze gradient``, ``analyze mass`` and ``analyze run`` on a synthetic signals table."""

import json

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import cli, pipeline
from haulprofile.analysis.vehicle import load_vehicle
from test_gradient import synthetic_drive, write_route_dem

TRUTH = ["true_gradient_pct", "true_height_m", "true_mass_kg", "in_tunnel"]


@pytest.fixture(scope="module")
def table_and_dem(tmp_path_factory):
    root = tmp_path_factory.mktemp("cmd")
    drive = synthetic_drive(seed=5, duration_s=1500, mass_kg=15_000).drop(columns=TRUTH + ["distance_m", "accel_mps2"])
    drive["reported_mass_kg"] = 15_400.0
    drive.to_parquet(root / "signals.parquet")
    dem = root / "dem"
    dem.mkdir()
    write_route_dem(dem)
    return root / "signals.parquet", dem


def test_analyze_gradient_writes_grid_and_figure(table_and_dem, tmp_path, capsys):
    table, dem = table_and_dem
    assert cli.main(["gradient", str(table), "--dem", str(dem), "--out", str(tmp_path)]) == 0
    grid = pd.read_csv(tmp_path / "gradient.csv")
    assert {"height_map_m", "height_baro_m", "height_m", "gradient_pct", "weight_map", "gradient_imu_pct"} <= set(grid)
    assert (tmp_path / "gradient.png").stat().st_size > 10_000
    assert "km on a 10 m grid" in capsys.readouterr().out


def test_analyze_mass_prints_all_methods_beside_can(table_and_dem, tmp_path, capsys):
    table, dem = table_and_dem
    assert cli.main(["mass", str(table), "--vehicle", "rigid-18t", "--dem", str(dem), "--out", str(tmp_path),
                     "--true-mass", "15000"]) == 0
    out = capsys.readouterr().out
    assert "LS" in out and "RLS" in out and "LM" in out and "CAN" in out and "15400" in out
    segments = json.loads((tmp_path / "mass.json").read_text())["segments"]
    ok = [s for s in segments if s["status"] == "ok"]
    assert ok and all(abs(s["mass_ls_kg"] / 15_000 - 1) < 0.03 for s in ok)
    assert (tmp_path / "mass.png").stat().st_size > 10_000


def test_analyze_mass_on_a_table_without_engine_data_is_one_line(table_and_dem, tmp_path, capsys):
    table, _ = table_and_dem
    bare = pd.read_parquet(table).drop(columns=["engine_torque_nm"])
    bare.to_csv(tmp_path / "bare.csv", index=False)
    assert cli.main(["mass", str(tmp_path / "bare.csv"), "--vehicle", "rigid-18t", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "engine_torque_nm" in err[0]


def test_run_pipeline_adds_columns_and_segment_masses(table_and_dem, tmp_path, monkeypatch):
    table, dem = table_and_dem
    monkeypatch.setattr(pipeline, "STAGES", [s for s in pipeline.STAGES if s.name in ("kinematics", "gradient", "mass")])
    ctx = pipeline.RunContext(inputs=[table], out_dir=tmp_path, vehicle=load_vehicle("rigid-18t"), dem_dir=dem,
                              say=lambda _m: None)
    pipeline.run(ctx)
    signals = pd.read_parquet(tmp_path / "signals.parquet")
    assert {"distance_m", "height_m", "gradient_pct", "mass_kg"} <= set(signals)
    summary = json.loads((tmp_path / "summary.json").read_text())
    segments = summary["mass"]["segments"]
    assert segments and {"start_s", "end_s", "n_samples", "mass_ls_kg", "mass_rls_kg", "mass_lm_kg",
                         "uncertainty_kg", "reported_mass_kg", "status", "reason"} <= set(segments[0])
    assert np.nanmedian(signals["mass_kg"]) == pytest.approx(15_000, rel=0.03)


def test_run_pipeline_without_dem_says_barometric_only(table_and_dem, tmp_path, monkeypatch):
    table, _ = table_and_dem
    monkeypatch.setattr(pipeline, "STAGES", [s for s in pipeline.STAGES if s.name in ("kinematics", "gradient")])
    said = []
    pipeline.run(pipeline.RunContext(inputs=[table], out_dir=tmp_path, say=said.append))
    assert any("barometric height only" in s for s in said)
    assert "gradient_pct" in pd.read_parquet(tmp_path / "signals.parquet")


def test_run_pipeline_on_a_drive_without_valid_samples_says_so_and_gives_no_number(table_and_dem, tmp_path,
                                                                                   monkeypatch):
    table, dem = table_and_dem
    broken = pd.read_parquet(table).assign(valid=False)
    broken.to_parquet(tmp_path / "invalid.parquet")
    monkeypatch.setattr(pipeline, "STAGES", [s for s in pipeline.STAGES if s.name in ("kinematics", "gradient", "mass")])
    said = []
    pipeline.run(pipeline.RunContext(inputs=[tmp_path / "invalid.parquet"], out_dir=tmp_path / "out",
                                     vehicle=load_vehicle("rigid-18t"), dem_dir=dem, say=said.append))
    assert any("gradient: skipped" in s and "no valid samples" in s for s in said)
    assert any(s.startswith("mass: skipped") and "gradient_pct" in s for s in said)
    signals = pd.read_parquet(tmp_path / "out" / "signals.parquet")
    assert "mass_kg" not in signals or signals["mass_kg"].isna().all()


def test_known_mass_and_gradient_method_options(table_and_dem, tmp_path, capsys):
    table, dem = table_and_dem
    assert cli.main(["mass", str(table), "--vehicle", "rigid-18t", "--dem", str(dem), "--out", str(tmp_path),
                     "--no-figure", "--known-mass", "1=15000", "--gradient-method", "paper"]) == 0
    out = capsys.readouterr().out
    assert "torque gain calibrated from segment(s) [1]" in out
    mass = json.loads((tmp_path / "mass.json").read_text())
    assert mass["segments"][0]["mass_kg"] == 15_000 and mass["road_load"]["torque_gain"]["calibrated_from"] == [1]
    assert cli.main(["mass", str(table), "--vehicle", "rigid-18t", "--out", str(tmp_path), "--known-mass", "7=1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--known-mass" in err[0]
