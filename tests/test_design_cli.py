"""``analyze design``: a VECTO cycle and a run folder in, the concept out as a vehicle file that
``analyze simulate`` accepts; bad input as one line or a stated "no feasible concept" (exit 3)."""

import json
import re
import shutil
import subprocess

import pytest

from haulprofile.analysis.cli import main

SMALL = ["--population", "16", "--generations", "6"]


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    from pathlib import Path

    cycle = Path(__file__).parent / "data" / "vecto-cycles" / "MunicipalUtility.vdri"
    out = tmp_path_factory.mktemp("design")
    code = main(["design", str(cycle), "--vehicle", "rigid-18t", "--out", str(out), "--daily-distance-km", "120",
                 *SMALL])
    return code, cycle, out


def test_design_writes_the_concept_and_its_files(designed):
    code, _, out = designed
    assert code == 0
    summary = json.loads((out / "design-summary.json").read_text())
    for name in summary["files"]:
        assert (out / name).stat().st_size > 0
    assert {"design/pareto.csv", "design/concept.toml", "design/requirements.csv", "design/pareto.png"} <= set(
        summary["files"])
    assert summary["requirements"]["peak_wheel_power_w"]["low"] <= summary["requirements"]["peak_wheel_power_w"]["high"]
    html = (out / "design-report.html").read_text()
    assert "What this application needs" in html and "data:image/png;base64" in html


def test_concept_file_drives_in_analyze_simulate_with_the_designed_energy(designed, tmp_path, capsys):
    code, cycle, out = designed
    concept = json.loads((out / "design-summary.json").read_text())["concept"]
    assert main(["simulate", str(cycle), "--vehicle", str(out / "design" / "concept.toml"), "--time-step-s", "0.5",
                 "--out", str(tmp_path / "sim")]) == 0
    simulated = json.loads((tmp_path / "sim" / "summary.json").read_text())
    # the concept's curb mass carries its powertrain; the default payload is the same half payload
    assert simulated["battery_kwh_per_km"] == pytest.approx(concept["battery_kwh_per_km"], rel=1e-3)


@pytest.mark.parametrize("flags, words", [
    (["--design-grade-pct", "80"], "design_grade_pct 80"),
    (["--machine-power-kw", "400", "100"], "design space is empty"),
    (["--battery-kwh", "0", "100"], "design space is empty"),
    (["--energy-price-eur-per-kwh", "-1"], "energy_price_eur_per_kwh -1"),
    (["--service-life-years", "0"], "service_life_years 0"),
])
def test_bad_targets_are_one_line(data_dir, tmp_path, capsys, flags, words):
    code = main(["design", str(data_dir / "vecto-cycles" / "MunicipalUtility.vdri"), "--vehicle", "rigid-18t",
                 "--out", str(tmp_path / "o"), *SMALL, *flags])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert words in err and "\n" not in err and "Traceback" not in err


@pytest.mark.parametrize("flags, binding", [
    (["--daily-distance-km", "3000", "--battery-kwh", "100", "200"], "range with reserve"),
    (["--startability-grade-pct", "35", "--machine-power-kw", "40", "60", "--max-machines", "1"], "startability"),
])
def test_unreachable_targets_are_no_feasible_concept(data_dir, tmp_path, capsys, flags, binding):
    code = main(["design", str(data_dir / "vecto-cycles" / "MunicipalUtility.vdri"), "--vehicle", "rigid-18t",
                 "--out", str(tmp_path / "o"), *SMALL, *flags])
    out = capsys.readouterr().out
    assert code == 3
    assert "no feasible concept" in out and binding in out


def test_missing_source_and_non_run_folder(tmp_path, capsys):
    assert main(["design", str(tmp_path / "nothing.vdri"), "--vehicle", "rigid-18t", "--out", str(tmp_path / "o")]) == 2
    (tmp_path / "empty").mkdir()
    assert main(["design", str(tmp_path / "empty"), "--vehicle", "rigid-18t", "--out", str(tmp_path / "o")]) == 2
    assert "not an 'analyze run' output folder" in capsys.readouterr().err


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
IMAGE_PROBE = """<script>window.addEventListener('load', () => {
  const images = [...document.images];
  document.body.dataset.loaded = images.filter(i => i.complete && i.naturalWidth > 100).length + ':' + images.length;
});</script>"""


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not installed (Debian package chromium)")
def test_design_report_renders_in_headless_chromium(designed, tmp_path):
    _, _, out = designed
    page = tmp_path / "probe.html"
    page.write_text((out / "design-report.html").read_text().replace("</body>", IMAGE_PROBE + "</body>"))
    dom = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                          "--disable-background-networking", "--disable-component-update", "--disable-sync",
                          f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=3000", "--dump-dom",
                          page.as_uri()], check=True, capture_output=True, text=True, timeout=120).stdout
    loaded = re.search(r'data-loaded="(\d+):(\d+)"', dom)
    assert loaded and int(loaded.group(2)) >= 2 and loaded.group(1) == loaded.group(2), "every figure decoded"
    assert "What this application needs" in dom and "Requirements at the wheel" in dom
    text = re.sub(r"<[^>]+>", " ", re.sub(r"<(script|style)[^>]*>.*?</\1>", " ", dom, flags=re.S))
    assert not re.search(r"\b(nan|inf|undefined)\b", text, re.I)


def test_design_summary_is_strict_json(designed):
    _, _, out = designed

    def refuse(name):
        raise AssertionError(f"{name} in design-summary.json")

    summary = json.loads((out / "design-summary.json").read_text(), parse_constant=refuse)
    assert summary["schema_version"] == 1 and summary["concept"]["shaft_requirements"]


def test_design_stage_on_a_signals_table_and_its_skip(tmp_path):
    import numpy as np
    import pandas as pd

    from haulprofile.analysis.design import DesignOptions
    from haulprofile.analysis.pipeline import Options, RunContext, run
    from haulprofile.analysis.vehicle import load_vehicle

    time = np.arange(0.0, 900.0)
    speed = np.clip(np.minimum(time, 900 - time) * 0.6, 0.0, 22.0)
    drive = pd.DataFrame({"time_s": time, "speed_mps": speed, "accel_mps2": np.gradient(speed, time),
                          "gradient_pct": 2.0 * np.sin(time / 120.0), "mass_kg": 15_000.0})
    options = Options(design=DesignOptions(population=8, generations=2))
    ctx = RunContext(inputs=[], out_dir=tmp_path / "run", vehicle=load_vehicle("rigid-18t"), options=options,
                     signals=drive, say=lambda _m: None)
    run(ctx, start="simulation", until="design")
    assert ctx.summary["design"]["drives"] == ["measured drive"]
    assert ctx.summary["design"]["cycles"] == ["measured drive"]
    assert (tmp_path / "run" / "design" / "pareto.csv").is_file()
    still = drive.assign(speed_mps=0.0, accel_mps2=0.0)
    ctx = RunContext(inputs=[], out_dir=tmp_path / "still", vehicle=load_vehicle("rigid-18t"), options=options,
                     signals=still, say=lambda _m: None)
    run(ctx, start="simulation", until="design")
    assert "design" not in ctx.summary and "100 m" in ctx.skipped["design"]


def test_a_machine_capped_by_its_inverter_is_stated_with_what_it_delivers():
    """The concept's line gives the machine's rating and, where the inverter's current caps it,
    the power the concept has: "1 x 258 kW" alone overstated a 233 kW concept."""
    from haulprofile.analysis.design.chapter import machines_text

    capped = {"machines": 1, "machine_peak_power_w": 258_400.0, "total_peak_power_w": 233_500.0}
    assert machines_text(capped) == "1 x 258 kW (234 kW with its inverter)"
    two = {"machines": 2, "machine_peak_power_w": 300_000.0, "total_peak_power_w": 540_000.0}
    assert machines_text(two) == "2 x 300 kW (540 kW with their inverters)"
    assert machines_text({"machines": 2, "machine_peak_power_w": 300_000.0, "total_peak_power_w": 600_000.0}) == \
        "2 x 300 kW"


@pytest.mark.parametrize("command", ["demo", "run"])
def test_run_and_demo_take_the_cost_of_ownership_figures_and_refuse_bad_ones_in_one_line(command, tmp_path, capsys):
    """`analyze run` and `analyze demo` end in the design stage: the energy price, service life and
    operating days of its choice are theirs to set, and a bad one stops them before any work."""
    import argparse

    from haulprofile.analysis.cli import main
    from haulprofile.analysis.commands.arguments import add_design_search, design_options

    parser = argparse.ArgumentParser()
    add_design_search(parser)
    options = design_options(parser.parse_args(["--energy-price-eur-per-kwh", "0.45", "--service-life-years", "8",
                                                "--operating-days", "300"]))
    assert (options.energy_price_eur_per_kwh, options.service_life_years, options.operating_days_per_year) == \
        (0.45, 8.0, 300.0)
    args = [command] + (["--out", str(tmp_path / "out")] if command == "demo" else
                        [str(tmp_path), "--vehicle", "rigid-18t", "--out", str(tmp_path / "out")])
    assert main(args + ["--energy-price-eur-per-kwh", "40"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "energy_price_eur_per_kwh" in err[0]
    assert not (tmp_path / "out").exists()
