"""``analyze fleet`` on a small virtual fleet: one truck, three short logs whose engine torque report
is 4 % high in every log. One weighbridge ticket (``--known-mass TRUCK:LOG:SEGMENT=KG``) calibrates
the truck's torque gain, and every other segment of every log comes within 2.5 % of its true mass;
the c_r shared by the three logs is nearer the truth than the logs' own (RMS)."""

import json

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.cli import main
from haulprofile.testing.fleet import virtual_fleet
from haulprofile.analysis.vehicle import load_vehicle

pytest.importorskip("haulprofile.analysis.virtual_truck")

GAIN = 1.04
TRUE_C_R = load_vehicle("rigid-18t").rolling_resistance_coefficient  # the ideal level drives the vehicle file


@pytest.fixture(scope="module")
def truck_fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("truck-fleet")
    (truck_dir,), dem_dir = virtual_fleet(root, {"truck": ("urban-delivery", "rigid-18t")}, 3, n_sections=7,
                                          realism="ideal", torque_gains={"truck": GAIN}, say=lambda _m: None)
    return root, truck_dir, dem_dir


def true_mass_kg(root, log, time_s):
    truth = pd.read_csv(root / "truth" / "truck" / f"{log.rsplit('.', 1)[0]}-mass.csv")
    return float(truth["mass_kg"][(truth["start_s"] <= time_s) & (truth["end_s"] >= time_s)].iloc[0])


def test_one_weighing_calibrates_every_log_of_the_truck(truck_fleet, tmp_path, capsys):
    root, truck_dir, dem_dir = truck_fleet
    weighed = true_mass_kg(root, "drive-00.mcap", 0.0)
    code = main(["fleet", str(truck_dir), "--vehicle", "rigid-18t", "--dem", str(dem_dir), "--out", str(tmp_path),
                 "--workers", "1", "--no-figures", "--candidates", "300", "--duration", "600",
                 "--known-mass", f"truck:drive-00.mcap:1={weighed}", "--json"])
    out, err = capsys.readouterr()
    assert code in (0, 3), err
    assert json.loads(out)["groups"][0]["road_load"]["torque_gain"]["calibrated_from"] == [
        {"log": "drive-00.mcap", "segment": 1}]
    summary = json.loads((tmp_path / "truck" / "fleet-summary.json").read_text())
    road_load = summary["road_load"]
    print(json.dumps({k: v for k, v in road_load.items() if k != "segments"}, indent=1))
    assert road_load["logs"] == 3
    assert road_load["torque_gain"]["gain"] == pytest.approx(GAIN, abs=0.01)
    segments = pd.read_csv(tmp_path / "truck" / "truck_masses.csv")
    assert len(segments) >= 4 and segments["log"].nunique() == 3
    true = np.array([true_mass_kg(root, s.log, (s.start_s + s.end_s) / 2) for s in segments.itertuples()])
    error = segments["mass_kg"].to_numpy() / true - 1
    print("mass errors after one weighing [%]", np.round(100 * error, 2))
    assert error[0] == 0 and np.all(np.abs(error) < 0.025)
    assert np.all((np.abs(segments["mass_kg"] - true) < 2.5 * segments["mass_uncertainty_kg"])[1:])
    shared = road_load["rolling_resistance_coefficient"]
    own = np.array([log["rolling_resistance_coefficient"]["value"] for log in road_load["per_log"]])
    print("c_r shared", shared, "own", own)
    assert shared["identified"] and len(own) == 3
    assert abs(shared["value"] - TRUE_C_R) < np.sqrt(np.mean((own - TRUE_C_R) ** 2))
    assert own.min() <= shared["value"] <= own.max()


def test_a_known_mass_of_a_log_that_is_not_there_is_one_line(truck_fleet, tmp_path, capsys):
    _, truck_dir, dem_dir = truck_fleet
    code = main(["fleet", str(truck_dir), "--vehicle", "rigid-18t", "--dem", str(dem_dir), "--out", str(tmp_path),
                 "--workers", "1", "--known-mass", "truck:drive-09.mcap:1=16000"])
    err = capsys.readouterr().err
    assert code == 2 and "drive-09.mcap" in err and "Traceback" not in err
    code = main(["fleet", str(truck_dir), "--vehicle", "rigid-18t", "--dem", str(dem_dir), "--out", str(tmp_path),
                 "--workers", "1", "--known-mass", "lorry:drive-00.mcap:1=16000"])
    assert code == 2 and "no truck" in capsys.readouterr().err


def test_a_weighed_segment_without_a_joint_fit_is_a_warning(truck_fleet, tmp_path, capsys):
    _, truck_dir, dem_dir = truck_fleet
    code = main(["fleet", str(truck_dir), "--vehicle", "rigid-18t", "--dem", str(dem_dir), "--out", str(tmp_path),
                 "--workers", "1", "--no-figures", "--candidates", "300", "--duration", "600",
                 "--known-mass", "truck:drive-00:9=16000"])
    warnings = [line for line in capsys.readouterr().err.splitlines() if "road load" in line]
    assert code == 3 and len(warnings) == 1 and "drive-00.mcap segment 9" in warnings[0]
    summary = json.loads((tmp_path / "truck" / "fleet-summary.json").read_text())
    assert "segment 9" in summary["road_load"]["error"] and not (tmp_path / "truck" / "truck_masses.csv").exists()


def key_paths(value, prefix=""):
    if isinstance(value, dict):
        for key, item in value.items():
            yield from key_paths(item, f"{prefix}.{key}" if prefix else key)
    elif isinstance(value, list) and value and all(isinstance(item, dict) for item in value):
        for item in value:
            yield from key_paths(item, prefix + "[]")
    else:
        yield prefix


def test_every_road_load_key_is_documented(truck_fleet, tmp_path):
    import re
    from pathlib import Path

    from haulprofile.analysis.fleet import FleetSpec, run_fleet
    root, truck_dir, dem_dir = truck_fleet
    spec = FleetSpec.of([truck_dir], [load_vehicle("rigid-18t")], dem_dir=dem_dir, n_candidates=300, duration_s=600.0,
                        figures=False, known_masses=[("truck", "drive-01", 1, true_mass_kg(root, "drive-01.mcap", 0.0))])
    run_fleet(spec, tmp_path, workers=1, say=lambda _m: None)
    road_load = json.loads((tmp_path / "truck" / "fleet-summary.json").read_text())["road_load"]
    doc = (Path(__file__).parents[1] / "docs" / "fleet.md").read_text()
    documented = [key for cell in re.findall(r"^\| (`[^|]+)\|", doc, flags=re.M) for key in re.findall(r"`([^`]+)`", cell)]
    missing = sorted({p for p in key_paths(road_load) if not any(p == k or p.startswith(k + ".") for k in documented)})
    assert not missing, f"road_load keys missing from docs/fleet.md: {missing}"
