"""The accuracy matrix's drives through the real analysis, with loose floors so that a broken
estimator or a broken virtual world shows (the full matrix: ``python tools/bench.py accuracy``)."""

import numpy as np
import pytest

from haulprofile.testing.accuracy import Case, case_scenario, run_case


@pytest.fixture(scope="module")
def ideal():
    return run_case(Case("urban-delivery", "ideal", 0, 5000.0))


@pytest.fixture(scope="module")
def typical():
    return run_case(Case("long-haul", "typical", 0, 12000.0, 300.0))


def test_a_case_is_the_shipped_scenario_cut_with_a_stop_added():
    scenario = case_scenario(Case("long-haul", "typical", 0, 8000.0, 300.0))
    lengths = [s.length_m for s in scenario.route.section]
    assert 7000.0 <= sum(lengths) <= 9000.0
    assert [s.stop_s for s in scenario.route.section].count(300.0) == 1


def test_ideal_drive_meets_the_old_worlds_figures(ideal):
    gradient = ideal["gradient"]
    assert gradient["fusion"]["outside"] < 0.3 and gradient["baro"]["outside"] < 0.15
    assert gradient["map"]["outside"] < 0.5
    errors = np.abs(ideal["mass"]["exact"]["fusion"]["mass_ls_kg"])
    assert len(errors) >= 1 and np.median(errors) < 0.03


def test_typical_drive_is_harder_but_not_broken(ideal, typical):
    gradient = typical["gradient"]
    assert typical["injected"]["trailer_change_stop"] == 1
    assert gradient["baro"]["outside"] < 0.8 and gradient["fusion"]["outside"] < 2.0
    assert gradient["map"]["outside"] < 3.0
    assert gradient["map"]["outside"] > ideal["gradient"]["map"]["outside"], "the DEM is terrain, not road"
    found = [abs(e) for e in typical["mass"]["exact"]["baro"]["mass_ls_kg"]]
    assert found and np.median(found) < 0.2
    assert "smoother" not in gradient or gradient["smoother"]["outside"] < 2.0


def test_the_new_estimator_is_used_when_the_gradient_stage_offers_it(monkeypatch, tmp_path):
    import dataclasses
    from types import SimpleNamespace

    import pandas as pd

    from haulprofile.analysis import dem, gradient
    from haulprofile.testing import accuracy

    @dataclasses.dataclass(frozen=True)
    class Settings:
        gradient_method: str = "smoother"

    def estimate(signals, _dem, settings):
        column = {"paper": "gradient_pct", "smoother": "gradient_smooth_pct"}[settings.gradient_method]
        return SimpleNamespace(samples={column: np.full(len(signals), 1.0 if column == "gradient_pct" else 2.0)})

    signals = pd.DataFrame({"time_s": [0.0, 0.1], "gradient_pct": [5.0, 5.0]})
    assert list(accuracy._gradient_columns(signals, tmp_path).columns) == ["time_s", "gradient_pct"]
    monkeypatch.setattr(gradient, "GradientSettings", Settings)
    monkeypatch.setattr(gradient, "estimate_gradient", estimate)
    monkeypatch.setattr(dem, "open_dem", lambda _directory: None)
    out = accuracy._gradient_columns(signals, tmp_path)
    assert list(out["gradient_pct"]) == [1.0, 1.0] and list(out["gradient_smooth_pct"]) == [2.0, 2.0]


def test_every_sensor_set_is_scored_and_none_is_broken(ideal, typical):
    """The sensor sets real loggers have, with loose floors: without a barometer the IMU leads,
    without both the force balance, with nothing but CAN the force balance on the given mass
    still beats a flat road."""
    from haulprofile.testing.accuracy import SENSOR_SETS
    for case in (ideal, typical):
        assert set(case["sensor_sets"]) == set(SENSOR_SETS)
        assert case["sensor_sets"]["full"]["gradient"] == case["gradient"]
        assert case["sensor_sets"]["can-only"]["mass"] == {}, "the mass is given there"
    sets = typical["sensor_sets"]
    assert sets["no-baro"]["gradient"]["smoother"]["outside"] < 0.3
    assert sets["no-baro"]["gradient_within_2_sigma"]["smoother"] > 0.8
    assert sets["no-imu"]["gradient"]["smoother"]["outside"] < 0.3
    assert sets["gps+can"]["gradient"]["smoother"]["outside"] < 0.6 * sets["gps+can"]["gradient"]["map"]["outside"]
    assert "baro" not in sets["gps+can"]["gradient"] and "fusion" not in sets["can-only"]["gradient"] or \
        sets["can-only"]["gradient"]["fusion"]["outside"] is None
    flat = sets["can-only"]["gradient"]["flat"]["outside"]
    assert sets["can-only"]["gradient"]["smoother"]["outside"] < 0.6 * flat
    assert ideal["sensor_sets"]["no-baro"]["gradient"]["smoother"]["outside"] < 0.15


def test_without_barometer_and_imu_the_gradient_sigma_covers_the_truth(ideal, typical):
    """`gps+can`: the force balance's own noise (not the GPS gradient's error), the first pass's
    road curvature from the data and its mass's stated sigma with the gradient's: the truth inside
    ±2σ on at least 90 % of the bins of the urban drive (before: 54 %) and 85 % of the long-haul
    one (before: 73 %; its first segment's mass is 15 % off with a stated 6 %)."""
    for case, floor in ((ideal, 0.9), (typical, 0.85)):
        assert case["sensor_sets"]["gps+can"]["gradient_within_2_sigma"]["smoother"] >= floor


def test_the_road_curvature_grid_reaches_an_urban_streets():
    """The mean square change of the matrix's urban roads' gradient is 5e-6 to 1.3e-5 per metre
    over 50-200 m, beyond the curvature grid's old top (3e-6): on urban `typical` seed 1 the first pass (GPS
    altitude and the DEM) was too stiff and too flat (2.0 %-pt), its masses 10-58 % heavy, and the
    `gps+can` gradient 1.58 %-pt with 86 % of the bins inside ±2σ. With 1e-5 and 3e-5 on the grid
    the likelihood takes 1e-5 there: 1.37 %-pt, 94 % inside."""
    case = run_case(Case("urban-delivery", "typical", 1, 8000.0, dem="geotiff"), sensor_sets=("gps+can",))
    scores = case["sensor_sets"]["gps+can"]
    assert scores["gradient"]["smoother"]["outside"] < 1.45
    assert scores["gradient_within_2_sigma"]["smoother"] >= 0.9


def test_each_scored_mass_carries_its_error_over_its_sigma(typical):
    """``mass_kg_z`` is (m̂ - m) / σ per segment scored for coverage, so |z| <= 2 is exactly the
    coverage flag (with one weighing too)."""
    for key in ("mass_kg", "mass_kg_weighed"):
        scores = typical["mass"]["exact"]["smoother"]
        z, inside = scores[f"{key}_z"], scores[f"{key}_within_2_sigma"]
        assert len(z) == len(inside)
        assert [abs(v) <= 2 for v in z] == inside
    assert typical["mass"]["exact"]["smoother"]["mass_kg_z"]


def test_the_summary_gives_the_rms_of_the_masses_error_over_sigma():
    """The matrix's line per cell pools ``mass_kg_z`` over its drives: RMS 1 where σ is honest."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from benchmarks.accuracy import summarise
    from haulprofile.testing.accuracy import CATEGORIES, MASS_KEYS

    def drive(z):
        mass = {key: [0.01] for key in MASS_KEYS} | {
            "mass_kg_within_2_sigma": [abs(v) <= 2 for v in z], "mass_kg_z": z,
            "mass_kg_weighed_within_2_sigma": [], "mass_kg_weighed_z": []}
        scores = {"gradient": {"smoother": {cat: 0.1 for cat in CATEGORIES}}, "gradient_within_2_sigma": {},
                  "mass": {"exact": {"smoother": mass}, "datasheet": {"smoother": mass}}}
        return {"case": {"level": "typical"}, "sensor_sets": {"full": scores}}

    lines = summarise([drive([1.0, -3.0]), drive([0.0, 2.0])])
    line = next(l for l in lines if l.get("method") == "smoother" and l.get("vehicle") == "exact")
    assert line["mass_error"]["mass_kg"]["rms_z"] == pytest.approx(np.sqrt((1 + 9 + 0 + 4) / 4))
    assert line["mass_error"]["mass_kg"]["within_2_sigma"] == 0.75
    assert "rms_z" not in line["mass_error"]["mass_kg_weighed"]


def test_other_seeds_draw_the_same_matrix_from_drives_not_tuned_on():
    """``ACCURACY_SEEDS`` swaps the default seeds (0-3) for others: the same 36 drive shapes."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from benchmarks.accuracy import matrix, seeds_from

    assert seeds_from("4-7") == (4, 5, 6, 7) and seeds_from("4, 9-10") == (4, 9, 10)
    assert seeds_from("") is None and seeds_from(None) is None
    default, other = matrix(False), matrix(False, seeds_from("4-7"))
    assert len(other) == len(default) == 36
    assert {c.seed for c in default} == {0, 1, 2, 3} and {c.seed for c in other} == {4, 5, 6, 7}
    shape = lambda c: (c.scenario, c.level, c.length_m, c.stop_s, c.dem)
    assert [shape(c) for c in other] == [shape(c) for c in default]
