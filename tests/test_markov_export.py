"""Outputs: CSV/Parquet/VECTO cycle, the VECTO round trip, real VECTO cycles as input, the stage
and ``analyze cycle``."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import cli
from haulprofile.analysis.markov import count_transitions, cycle_stage, cycle_to_vdri, select_cycle, write_cycle
from haulprofile.analysis.vecto import vdri_to_time_cycle
from haulprofile.testing.drives import synthetic_drive
from haulprofile.analysis.pipeline import RunContext, run
from haulprofile.analysis.vecto import read_vdri, vdri_problems

VALID_VECTO_ROUTES = ["Construction", "HeavyUrban", "Suburban", "UrbanDelivery"]


@pytest.fixture(scope="module")
def drive():
    return synthetic_drive(2 * 3600, seed=41, kind="urban", rate_hz=10.0)


@pytest.fixture(scope="module")
def selection(drive):
    return select_cycle(count_transitions(drive), 1800, 1000, seed=2)


def test_cycle_to_vdri_and_back_keeps_time_distance_and_stops(selection):
    cycle = selection.cycle
    vdri = cycle_to_vdri(cycle)
    assert np.diff(vdri["distance_m"]).min() >= 1.0
    stops = vdri["target_speed_mps"] == 0
    assert np.all(vdri.loc[stops.to_numpy()[:-1].nonzero()[0], "stop_time_s"] > 0)
    # creeping under 1 m between two stops becomes stop time
    assert vdri["stop_time_s"].sum() == pytest.approx((cycle["speed_mps"].to_numpy()[:-1] == 0).sum(), abs=3)
    back = vdri_to_time_cycle(vdri)
    assert len(back) == len(cycle)
    assert back["distance_m"].iloc[-1] == pytest.approx(cycle["distance_m"].iloc[-1], abs=1e-6)
    np.testing.assert_allclose(back["distance_m"], cycle["distance_m"], atol=0.001 * cycle["distance_m"].iloc[-1])
    # speeds differ only where rows under 1 m were joined into their mean speed
    assert np.mean(np.isclose(back["speed_mps"], cycle["speed_mps"], atol=1e-9)) > 0.95
    np.testing.assert_allclose(back["gradient_pct"], cycle["gradient_pct"], atol=1e-12)


@pytest.mark.parametrize("kind, seed", [("urban", 41), ("urban", 7), ("regional", 41), ("regional", 3)])
def test_every_exported_cycle_meets_vectos_rules(tmp_path, kind, seed):
    measured = synthetic_drive(3600, seed=seed, kind=kind, rate_hz=10.0)
    chosen = select_cycle(count_transitions(measured), 1200, 200, seed=seed)
    vdri = write_cycle(chosen.cycle, tmp_path)["vdri"]
    assert vdri_problems(vdri) == []
    back = vdri_to_time_cycle(read_vdri(vdri))
    assert abs(len(back) - len(chosen.cycle)) <= 2
    assert back["distance_m"].iloc[-1] == pytest.approx(chosen.cycle["distance_m"].iloc[-1], abs=0.01)


def test_vecto_rules_catch_sub_metre_and_zero_steps(tmp_path):
    path = tmp_path / "c.vdri"
    path.write_text("<s>,<v>,<grad>,<stop>\n0,0,0,2\n0,1,0,0\n0.28,2,0,0\n10,0,0,0\n")
    assert vdri_problems(path) == ["2 distance step(s) under 1 m, first at row 3"]
    path.write_text("<s>,<v>,<grad>,<stop>\n0,0,0,0\n5,20,0,3\n10,0,0,0\n")
    assert vdri_problems(path) == ["stop time on a row with a target speed", "a standstill row without stop time"]


def test_written_files_round_trip(selection, tmp_path):
    paths = write_cycle(selection.cycle, tmp_path)
    csv = pd.read_csv(paths["csv"])
    assert list(csv.columns) == ["time_s", "speed_mps", "accel_mps2", "gradient_pct", "mass_kg", "distance_m"]
    pd.testing.assert_frame_equal(pd.read_parquet(paths["parquet"]), selection.cycle)
    assert paths["vdri"].read_text().splitlines()[0] == "<s>,<v>,<grad>,<stop>"
    back = vdri_to_time_cycle(read_vdri(paths["vdri"]))
    assert np.mean(np.isclose(back["speed_mps"], selection.cycle["speed_mps"], atol=1e-3)) > 0.95
    np.testing.assert_allclose(back["distance_m"], selection.cycle["distance_m"],
                               atol=0.001 * selection.cycle["distance_m"].iloc[-1])


@pytest.mark.parametrize("name", ["LongHaul", "Urban", "Construction"])
def test_real_vecto_cycle_as_time_trace(data_dir, name):
    vdri = read_vdri(data_dir / "vecto-cycles" / f"{name}.vdri")
    trace = vdri_to_time_cycle(vdri)
    s, v, stop = (vdri[c].to_numpy() for c in ("distance_m", "target_speed_mps", "stop_time_s"))
    moving_speed = np.where(v > 0, v, [v[i + 1:][v[i + 1:] > 0][0] if np.any(v[i + 1:] > 0) else 1.0
                                        for i in range(len(v))])
    duration = np.sum(np.diff(s) / moving_speed[:-1]) + stop.sum()    # independent closed form
    assert trace["time_s"].iloc[-1] == pytest.approx(round(duration), abs=1)
    assert trace["distance_m"].iloc[-1] == pytest.approx(s[-1], abs=0.5)
    assert (trace["speed_mps"] == 0).sum() == pytest.approx(stop.sum(), abs=int((v == 0).sum()) + 1)


def _driven(trace, accel_mps2=0.6, decel_mps2=0.8):
    """A VECTO target trace as a truck would drive it: limited acceleration and braking."""
    v = trace["speed_mps"].to_numpy().copy()
    for k in range(1, len(v)):
        v[k] = min(v[k], v[k - 1] + accel_mps2)
    for k in range(len(v) - 2, -1, -1):
        v[k] = min(v[k], v[k + 1] + decel_mps2)
    rng = np.random.default_rng(0)
    mass = np.empty(len(v))
    mass[0] = 20_000.0
    for k in range(1, len(v)):
        arrived = v[k] == 0 and v[k - 1] > 0
        mass[k] = round(rng.uniform(14_000, 26_000), -1) if arrived and rng.random() < 0.5 else mass[k - 1]
    return trace.assign(speed_mps=v, mass_kg=mass)


@pytest.mark.parametrize("name", VALID_VECTO_ROUTES)
def test_real_vecto_routes_as_measured_input_give_valid_cycles(data_dir, name):
    measured = _driven(vdri_to_time_cycle(read_vdri(data_dir / "vecto-cycles" / f"{name}.vdri")))
    assert measured["mass_kg"].nunique() > 1
    selection = select_cycle(count_transitions(measured), 1800, 10_000, seed=1)
    assert selection.criteria.valid, selection.criteria.statement()
    assert selection.criteria.score <= 0.5


def test_stage_writes_the_cycle_and_its_summary(drive, tmp_path):
    messages = []
    ctx = RunContext(inputs=[], out_dir=tmp_path, signals=drive.copy(), say=messages.append,
                     options={"cycle": {"n_candidates": 500, "seed": 3, "widths": {"mass_kg": 200.0}}})
    run(ctx, start="cycle", until="cycle")
    for name in ("cycle.csv", "cycle.vdri", "cycle.parquet", "cycle.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert vdri_problems(tmp_path / "cycle.vdri") == []
    summary = ctx.summary["cycle"]
    assert summary["seed"] == 3 and summary["class_widths"]["mass_kg"] == 200.0
    assert set(summary) >= {"score", "valid", "criteria", "failed", "n_valid"}
    assert all({"deviation", "allowance"} <= set(c) for c in summary["criteria"].values())
    json.dumps(summary)
    assert "cycle:" in messages[-2] and re.fullmatch(r"\[cycle\] \d+\.\d s", messages[-1])  # then its time


def test_stage_without_mass_says_so_and_writes_nothing(drive, tmp_path):
    messages = []
    ctx = RunContext(inputs=[], out_dir=tmp_path, signals=drive.drop(columns=["mass_kg"]), say=messages.append)
    assert cycle_stage(ctx) is None
    assert "cycle" in ctx.skipped and "mass_kg" in messages[0]
    assert not (tmp_path / "cycle.csv").exists()


def test_analyze_cycle_command(drive, tmp_path, capsys):
    table = tmp_path / "signals.csv"
    drive.iloc[::10].to_csv(table, index=False)
    out = tmp_path / "out"
    argv = ["cycle", str(table), "--out", str(out), "--candidates", "400", "--seed", "5", "--duration", "900",
            "--mass-class-kg", "100", "--quiet"]
    code = cli.main(argv)
    summary = json.loads((out / "cycle.json").read_text())
    assert code == (0 if summary["valid"] else 3)
    first = pd.read_csv(out / "cycle.csv")
    assert len(first) == 901
    cli.main(argv)
    pd.testing.assert_frame_equal(pd.read_csv(out / "cycle.csv"), first)
    assert cli.main(["cycle", str(table), "--out", str(out), "--speed-class-kmh", "-1"]) == 2
    assert "speed_kmh" in capsys.readouterr().err
