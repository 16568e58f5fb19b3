"""The loads stage, ``analyze loads`` and the measured vs generated comparison."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.cli import main
from haulprofile.analysis.loads import collectives_of, compare
from haulprofile.analysis.loads.stage import LoadsOptions, loads_stage
from haulprofile.analysis.pipeline import Options, RunContext, run
from haulprofile.analysis.vehicle import load_vehicle


def drive(seconds: float, seed: int, mass_kg: float = 20_000.0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    time = np.arange(0.0, seconds, 0.5)
    speed = np.clip(15 + 6 * np.sin(time / 25) + np.cumsum(rng.normal(0, 0.05, len(time))), 0, None)
    return pd.DataFrame({"time_s": time, "speed_mps": speed, "accel_mps2": np.gradient(speed, time),
                         "gradient_pct": 3 * np.sin(time / 80), "mass_kg": mass_kg})


@pytest.fixture(scope="module")
def rigid():
    return load_vehicle("rigid-18t")


def test_identical_drives_compare_as_identical(rigid):
    measured = drive(1200, 1)
    collectives = collectives_of({"measured": measured, "generated": measured.copy()}, rigid)
    comparison = compare(collectives["measured"], collectives["generated"])
    np.testing.assert_allclose(comparison["relative_deviation"].to_numpy(), 0.0, atol=1e-12)


def test_heavier_cycle_shows_higher_damage_equivalent_torque(rigid):
    collectives = collectives_of({"measured": drive(1200, 1), "generated": drive(1200, 1, 30_000.0)}, rigid)
    comparison = compare(collectives["measured"], collectives["generated"]).set_index("criterion")
    for k in range(3, 11):
        assert comparison.loc[f"damage-equivalent torque range k={k} [Nm]", "relative_deviation"] > 0.2


def test_stage_writes_measured_and_generated(tmp_path, rigid):
    drive(600, 2).to_csv(tmp_path / "generated.csv", index=False)
    messages = []
    ctx = RunContext(inputs=[], out_dir=tmp_path, vehicle=rigid, signals=drive(1800, 1), say=messages.append,
                     options=Options(loads=LoadsOptions(generated_file=tmp_path / "generated.csv")))
    run(ctx, start="loads", until="loads")
    summary = ctx.summary["loads"]
    assert {"measured", "generated", "comparison"} <= set(summary)
    assert summary["measured"]["duration_s"] == pytest.approx(1799.5)
    for name in ("comparison.csv", "measured_rainflow_range_mean_counts.csv", "generated_time_at_level_wheel_power_w.csv",
                 "time_at_level.png", "matrices.png", "crossings_damage.png"):
        assert (tmp_path / "loads" / name).stat().st_size > 0
    hist = pd.read_csv(tmp_path / "loads" / "measured_time_at_level_wheel_torque_nm.csv")
    assert hist["time_s"].sum() == pytest.approx(1799.5)


def test_stage_says_what_is_missing(tmp_path, rigid):
    messages = []
    ctx = RunContext(inputs=[], out_dir=tmp_path, vehicle=rigid, say=messages.append,
                     signals=drive(100, 1).drop(columns=["mass_kg"]))
    assert loads_stage(ctx) is None
    assert "loads" in ctx.skipped and "mass_kg" in messages[0]


def test_cli_loads(tmp_path, capsys):
    drive(900, 1).to_parquet(tmp_path / "signals.parquet")
    drive(300, 5).to_csv(tmp_path / "cycle.csv", index=False)
    assert main(["loads", str(tmp_path / "signals.parquet"), "--vehicle", "tractor-40t", "--cycle",
                 str(tmp_path / "cycle.csv"), "--out", str(tmp_path / "o")]) == 0
    assert "damage-equivalent torque range k=5" in capsys.readouterr().out
    drive(100, 1).drop(columns=["gradient_pct"]).to_csv(tmp_path / "bad.csv", index=False)
    assert main(["loads", str(tmp_path / "bad.csv"), "--vehicle", "rigid-18t"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gradient_pct" in err


def test_drives_at_different_rates_are_counted_on_the_coarser_rate(rigid):
    fast = drive(1200, 1)
    fast_10hz = pd.DataFrame({c: np.interp(np.arange(0, 1199.5, 0.1), fast["time_s"], fast[c]) for c in fast.columns})
    fast_10hz["time_s"] = np.arange(0, 1199.5, 0.1)
    collectives = collectives_of({"measured": fast_10hz, "generated": fast}, rigid)
    assert collectives["measured"].duration_s == pytest.approx(collectives["generated"].duration_s, abs=0.6)
    ratio = collectives["measured"].rainflow["count"].sum() / collectives["generated"].rainflow["count"].sum()
    assert ratio == pytest.approx(1.0, abs=0.15)
    alone = collectives_of({"measured": fast_10hz}, rigid)["measured"]
    assert alone.duration_s == pytest.approx(1199.4)


def test_a_stop_without_a_mass_counts_with_the_mass_the_truck_arrived_with(tmp_path, rigid):
    """The mass stage leaves stops without a mass; the measured drive keeps them, as the generated
    cycle, which stands at its stops, does."""
    known = drive(1200, 1)
    stop = (known["time_s"] >= 300) & (known["time_s"] < 480)
    known.loc[stop, ["speed_mps", "accel_mps2"]] = 0.0
    estimated = known.assign(mass_kg=known["mass_kg"].where(~stop))
    summaries = []
    for signals in (known, estimated):
        ctx = RunContext(inputs=[], out_dir=tmp_path, vehicle=rigid, signals=signals, say=lambda _: None)
        run(ctx, start="loads", until="loads")
        summaries.append(ctx.summary["loads"]["measured"])
    assert summaries[1]["duration_s"] == pytest.approx(1199.5)
    assert summaries[1] == summaries[0]


def test_a_drive_averaged_to_a_coarser_rate_has_the_acceleration_that_rate_would_log(rigid):
    """Sub-second torque dips (gear shifts at 10 Hz) are not in a 1 Hz cycle: the 10 Hz drive
    averaged to 1 s gets the acceleration of its 1 s speeds by the kinematics stage's estimator,
    so it counts the same cycles as the same drive logged at 1 Hz, not the dips' share of them."""
    from haulprofile.analysis.kinematics import acceleration_mps2
    from haulprofile.analysis.loads import resample_mean
    time = np.arange(0.0, 1200.0, 0.1)
    speed = 12 + 4 * np.sin(time / 30) + 0.15 * np.sin(2 * np.pi * time / 0.8)
    fast = pd.DataFrame({"time_s": time, "speed_mps": speed, "accel_mps2": acceleration_mps2(time, speed, 0.3),
                         "gradient_pct": 1.0, "mass_kg": 18_000.0})
    averaged = resample_mean(fast, 1.0)
    logged = fast.groupby(np.floor(time + 1e-9)).mean().reset_index(drop=True)
    logged["time_s"] = np.arange(len(logged), dtype=float)
    logged["accel_mps2"] = acceleration_mps2(logged["time_s"].to_numpy(), logged["speed_mps"].to_numpy(), 1.0)
    np.testing.assert_allclose(averaged["accel_mps2"], logged["accel_mps2"], atol=1e-12)
    collectives = collectives_of({"measured": fast, "generated": logged}, rigid)
    assert collectives["measured"].damage_equivalent_torque_nm == pytest.approx(
        collectives["generated"].damage_equivalent_torque_nm, rel=1e-9)
