"""``analyze simulate`` and the pipeline stage."""

import json

import numpy as np
import pandas as pd

from haulprofile.analysis.cli import main
from haulprofile.analysis.markov.stage import STAGE as CYCLE
from haulprofile.analysis.pipeline import RunContext, run, run_stage
from haulprofile.analysis.simulate.stage import STAGE as SIMULATION, simulate_stage
from haulprofile.analysis.vehicle import load_vehicle


def test_cli_simulates_a_vecto_cycle(data_dir, tmp_path, capsys):
    out = tmp_path / "sim"
    code = main(["simulate", str(data_dir / "vecto-cycles" / "Construction.vdri"), "--vehicle", "tractor-40t",
                 "--aux-power-w", "5000", "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert 0.5 < summary["battery_kwh_per_km"] < 3.0
    for name in ("trace.parquet", "residence_s.csv", "misses.csv", "speed_soc.png", "machine_residence.png"):
        assert (out / name).stat().st_size > 0
    residence = pd.read_csv(out / "residence_s.csv", index_col=0)
    moving_s = summary["duration_s"] - summary["standstill_s"]
    assert abs(residence.to_numpy().sum() - moving_s) < 1e-6
    assert "kWh/km" in capsys.readouterr().out


def test_cli_time_based_csv_with_aux_series(tmp_path):
    time = np.arange(0.0, 200.0)
    pd.DataFrame({"time_s": time, "speed_mps": 10 * np.sin(np.pi * time / 199) ** 2}).to_csv(tmp_path / "t.csv", index=False)
    pd.DataFrame({"time_s": [0.0, 100.0], "power_w": [2000.0, 8000.0]}).to_csv(tmp_path / "aux.csv", index=False)
    assert main(["simulate", str(tmp_path / "t.csv"), "--vehicle", "rigid-18t", "--aux-power-w",
                 str(tmp_path / "aux.csv"), "--out", str(tmp_path / "o")]) == 0
    trace = pd.read_parquet(tmp_path / "o" / "trace.parquet")
    expected = np.interp(trace["time_s"] + 0.05, [0.0, 100.0], [2000.0, 8000.0]) * 0.1
    np.testing.assert_allclose(trace["auxiliary_energy_j"], expected)


def test_cli_bad_input_is_one_line(tmp_path, capsys):
    (tmp_path / "x.csv").write_text("a,b\n1,2\n")
    assert main(["simulate", str(tmp_path / "x.csv"), "--vehicle", "rigid-18t"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "time_s" in err


def test_stage_simulates_measured_drive_then_the_selected_cycle_in_memory(tmp_path):
    time = np.arange(0.0, 300.0)
    speed = np.interp(time, [0, 30, 200, 260, 299], [0, 15, 15, 0, 0])
    signals = pd.DataFrame({"time_s": time, "speed_mps": speed, "gradient_pct": 1.0, "mass_kg": 17_000.0})
    messages = []
    ctx = RunContext(inputs=[], out_dir=tmp_path, vehicle=load_vehicle("rigid-18t"), signals=signals,
                     say=messages.append)
    run(ctx, start="simulation", until="simulation")
    assert ctx.summary["simulation"]["cycle"] == "measured drive"
    assert ctx.summary["simulation"]["mean_mass_kg"] == 17_000.0
    assert (tmp_path / "simulation" / "summary.json").is_file()
    ctx.signals["mass_kg"] = 12_000.0
    ctx.options = ctx.options.of({"cycle": {"n_candidates": 50, "duration_s": 200.0}})
    run_stage(ctx, CYCLE)
    run_stage(ctx, SIMULATION)
    assert ctx.summary["simulation"]["cycle"] == "generated cycle"
    assert ctx.summary["simulation"]["mean_mass_kg"] == 12_000.0


def test_stage_without_electric_powertrain_says_so(tmp_path):
    import dataclasses
    messages = []
    ctx = RunContext(inputs=[], out_dir=tmp_path, say=messages.append,
                     vehicle=dataclasses.replace(load_vehicle("rigid-18t"), electric_powertrain=None))
    assert simulate_stage(ctx) is None
    assert "simulation" in ctx.skipped and "electric_powertrain" in messages[0]
