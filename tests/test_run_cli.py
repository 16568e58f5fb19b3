"""``analyze run`` as a user meets it: outputs, the stage cache, --json/--quiet, and one clear line
with a non-zero exit code for every kind of bad input."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.cli import main
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.analysis.virtual_truck import drive, load_scenario, write_dem, write_mcap

SMALL_DESIGN = ["--design-population", "16", "--design-generations", "4"]
"""A concept search of 64 candidates: what these tests check does not depend on its size."""


@pytest.fixture(scope="module")
def demo_inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("run")
    truck = drive(load_scenario("urban-delivery"), load_vehicle("rigid-18t"), seed=2)
    write_dem(truck, root / "dem")
    write_mcap(truck, root / "logs" / "drive.mcap")
    truck.truth.to_parquet(root / "truth.parquet")
    return root


def run_cli(capsys, *argv):
    code = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def first_run(demo_inputs, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "run"  # made by the run
    code = main(["run", str(demo_inputs / "logs"), "--vehicle", "rigid-18t", "--dem", str(demo_inputs / "dem"),
                 "--out", str(out), "--candidates", "1000", *SMALL_DESIGN, "--quiet"])
    return code, out


def test_run_writes_every_output(first_run):
    code, out = first_run
    assert code in (0, 3)
    signals = pd.read_parquet(out / "signals.parquet")
    for column in ("distance_m", "accel_mps2", "height_m", "gradient_pct"):
        assert column in signals and signals[column].notna().mean() > 0.5
    # mass only where a segment had enough excitation for a confident estimate
    assert signals["mass_kg"].notna().mean() > 0.2
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stages"][-1] == "report"
    for name in ("report.html", "cycle.csv", "cycle.vdri", "loads/comparison.csv", "simulation/summary.json"):
        assert (out / name).is_file(), name
    for name in ("signals.parquet", "report.html", "summary.json", "simulation/summary.json"):  # positions, times
        assert (out / name).stat().st_mode & 0o777 == 0o640, name
    for folder in (out, out / "loads", out / "simulation"):
        assert folder.stat().st_mode & 0o777 == 0o750, folder
    cached = [p for p in (out / ".cache").rglob("*") if p.is_file()]
    assert cached and all(p.stat().st_mode & 0o777 == 0o640 for p in cached)


def test_rerun_with_one_changed_option_reruns_only_what_depends_on_it(first_run, demo_inputs, capsys):
    _, out = first_run
    base = ["run", demo_inputs / "logs", "--vehicle", "rigid-18t", "--dem", demo_inputs / "dem", "--out", out,
            *SMALL_DESIGN, "--candidates", "1000"]
    code, printed, _ = run_cli(capsys, *base)
    assert "[ingest] unchanged, from cache" in printed and "[simulation] unchanged, from cache" in printed
    code, printed, _ = run_cli(capsys, *base[:-1], "1500")
    assert "[mass] unchanged, from cache" in printed and "[cycle] unchanged" not in printed
    assert "[cycle]" in printed and "[loads]" in printed
    code, printed, _ = run_cli(capsys, *base[:-1], "1500", "--payload-kg", "4000")
    assert "[loads] unchanged, from cache" in printed and "[simulation]" in printed
    assert "[simulation] unchanged" not in printed


def test_json_prints_only_the_summary(first_run, demo_inputs, capsys):
    _, out = first_run
    code, printed, _ = run_cli(capsys, "run", demo_inputs / "logs", "--vehicle", "rigid-18t", "--dem",
                               demo_inputs / "dem", "--out", out, "--candidates", "1000", *SMALL_DESIGN, "--json")
    assert json.loads(printed)["stages"]


def one_line_error(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def test_missing_file(tmp_path, capsys):
    code, _, err = run_cli(capsys, "run", tmp_path / "nope.mcap", "--vehicle", "rigid-18t", "--out", tmp_path / "o")
    assert code == 2 and "nope.mcap" in one_line_error(err) and "not found" in err


def test_unreadable_log(tmp_path, capsys):
    bad = tmp_path / "garbage.mcap"
    bad.write_bytes(np.random.default_rng(0).bytes(4096))
    code, _, err = run_cli(capsys, "run", bad, "--vehicle", "rigid-18t", "--out", tmp_path / "o")
    assert code == 2 and "garbage.mcap" in one_line_error(err)


def test_no_dem_tile_for_the_route(demo_inputs, tmp_path, capsys):
    from haulprofile.analysis.dem.srtm import write_hgt

    elsewhere = tmp_path / "dem"
    write_hgt(elsewhere / "N10E010.hgt", np.zeros((1201, 1201)))
    code, _, err = run_cli(capsys, "run", demo_inputs / "logs", "--vehicle", "rigid-18t", "--dem", elsewhere,
                           "--out", tmp_path / "o", "--quiet")
    line = one_line_error(err)
    assert code == 2 and ".hgt is missing" in line and "without --dem" in line


def test_vehicle_file_typo(demo_inputs, tmp_path, capsys):
    vehicle = tmp_path / "truck.toml"
    text = (load_vehicle.__globals__["resources"].files("haulprofile.analysis.data.vehicles") / "rigid-18t.toml").read_text()
    vehicle.write_text(text.replace("frontal_area_m2", "frontal_aera_m2"))
    code, _, err = run_cli(capsys, "run", demo_inputs / "logs", "--vehicle", vehicle, "--out", tmp_path / "o")
    assert code == 2 and "frontal_aera_m2" in one_line_error(err)


def test_no_valid_mass_segment(tmp_path, capsys):
    """A drive at constant speed on a flat road: nothing excites the mass."""
    time_s = np.arange(0, 1200, 0.1)
    speed = np.clip(time_s * 0.5, 0, 20.0)
    noise = np.random.default_rng(1).normal(0, 2.0, time_s.size)
    table = pd.DataFrame({"time_s": time_s, "speed_mps": speed, "engine_speed_rpm": 1200.0,
                          "engine_torque_nm": 300.0, "pressure_pa": 95_000.0 + noise})
    path = tmp_path / "flat.csv"
    table.to_csv(path, index=False)
    code, _, err = run_cli(capsys, "run", path, "--vehicle", "rigid-18t", "--out", tmp_path / "o", "--quiet",
                           "--candidates", "1", *SMALL_DESIGN)
    line = one_line_error(err)
    assert code == 3 and "no segment has enough excitation" in line


def test_no_valid_cycle(demo_inputs, tmp_path, capsys):
    """One Monte Carlo candidate of 60 s cannot meet the criteria of an hour's drive."""
    code, _, err = run_cli(capsys, "run", demo_inputs / "truth.parquet", "--vehicle", "rigid-18t",
                           "--out", tmp_path / "o", "--quiet", "--candidates", "1", "--cycle-duration", "60",
                           *SMALL_DESIGN)
    line = one_line_error(err)
    assert code == 3 and "no valid cycle" in line and "--candidates" in line


def _strict(text):
    def refuse(constant):
        raise ValueError(f"bare {constant} in JSON")

    return json.loads(text, parse_constant=refuse)


def _key_paths(value, prefix=""):
    """Every leaf of a summary as ``a.b``, list elements as ``a[]``."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _key_paths(item, f"{prefix}.{key}" if prefix else key)
    elif isinstance(value, list) and value and all(isinstance(item, dict) for item in value):
        for item in value:
            yield from _key_paths(item, prefix + "[]")
    else:
        yield prefix


def _documented_patterns():
    import re
    from pathlib import Path

    doc = (Path(__file__).parents[1] / "docs" / "summary-json.md").read_text()
    keys = re.findall(r"^\| `([^`]+)` \|", doc, flags=re.M)
    return [re.compile("^" + re.escape(k).replace(r"\*", ".+") + "$") for k in keys]


def test_summary_json_is_strict_versioned_and_every_key_documented(first_run):
    _, out = first_run
    summary = _strict((out / "summary.json").read_text())
    assert summary["schema_version"] == 1
    patterns = _documented_patterns()
    undocumented = sorted({p for p in _key_paths(summary) if not any(r.match(p) for r in patterns)})
    assert not undocumented, f"keys missing from docs/summary-json.md: {undocumented}"


def test_json_on_stdout_is_strict(demo_inputs, first_run, capsys):
    _, out = first_run
    code, stdout, _ = run_cli(capsys, "run", demo_inputs / "logs", "--vehicle", "rigid-18t", "--dem",
                              demo_inputs / "dem", "--out", out, "--candidates", "1000", *SMALL_DESIGN, "--json")
    assert code in (0, 3) and _strict(stdout)["schema_version"] == 1
def test_private_run_keeps_positions_out_of_the_outputs(demo_inputs, first_run, tmp_path):
    _, normal = first_run
    assert {"latitude_deg", "longitude_deg", "wall_time_ns"} <= set(pd.read_parquet(normal / "signals.parquet"))
    out = tmp_path / "private"
    code = main(["run", str(demo_inputs / "logs"), "--vehicle", "rigid-18t", "--dem", str(demo_inputs / "dem"),
                 "--out", str(out), "--candidates", "1000", *SMALL_DESIGN, "--quiet", "--private"])
    assert code in (0, 3)
    signals = pd.read_parquet(out / "signals.parquet")
    assert not {"latitude_deg", "longitude_deg", "wall_time_ns"} & set(signals)
    for column in ("height_m", "gradient_pct", "distance_m"):  # the DEM was still used, in memory
        assert signals[column].notna().mean() > 0.5
    truth = pd.read_parquet(demo_inputs / "truth.parquet")
    lat_col = next(c for c in truth if c.startswith("lat"))
    lon_col = next(c for c in truth if c.startswith("lon"))
    texts = [f"{v:.4f}".encode() for v in (*truth[lat_col].iloc[::50], *truth[lon_col].iloc[::50])]
    # a coordinate starts a number: 6.1804 inside a mass of 11846.1804... is no position
    # one alternation, one pass over each file (a pattern per position took a minute on the report)
    pattern = re.compile(rb"(?<![0-9])(?:" + b"|".join(re.escape(t) for t in sorted(set(texts))) + rb")")
    for name in ("report.html", "summary.json"):
        found = pattern.findall((out / name).read_bytes())
        assert not found, (name, found[:5])
    assert not (out / ".cache").exists()
