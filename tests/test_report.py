"""The report: self-contained, every chapter present with its figures, every image a real PNG with
data drawn in it, no NaN in its text, tick labels apart, and it renders (and zooms) in Chromium."""

import base64
import io
import re
import shutil
import subprocess
from types import SimpleNamespace

import matplotlib.figure
import numpy as np
import pandas as pd
import pytest
from PIL import Image

from haulprofile.analysis.mass.figure import _mass_limits_t
from haulprofile.analysis.pipeline import RunContext, run
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.analysis.virtual_truck import drive, load_scenario, write_dem, write_mcap

CHROMIUM = shutil.which("chromium")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not installed (Debian package chromium)")
CROWDED: list[str] = []
"""Tick labels that touch or overlap, in any figure a stage saved while the report was made."""


def _crowded_ticks(figure) -> list[str]:
    """Neighbouring tick labels of any axis closer than 2 px (they read as one number)."""
    renderer = figure.canvas.get_renderer()
    found = []
    for ax in figure.axes:
        for axis, lo, hi in ((ax.xaxis, "x0", "x1"), (ax.yaxis, "y0", "y1")):
            labels = [t for t in axis.get_ticklabels() if t.get_visible() and t.get_text()]
            boxes = sorted(((t.get_window_extent(renderer), t.get_text()) for t in labels),
                           key=lambda b: getattr(b[0], lo))
            for (a, text_a), (b, text_b) in zip(boxes, boxes[1:]):
                if getattr(b, lo) < getattr(a, hi) + 2:
                    found.append(f"{ax.get_xlabel() if axis is ax.xaxis else ax.get_ylabel()}: {text_a} | {text_b}")
    return found


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    scenario = load_scenario("regional-tunnel")
    truck = drive(scenario, load_vehicle("rigid-18t"), seed=3)
    write_dem(truck, out / "dem")
    write_mcap(truck, out / "logs" / "drive.mcap")
    savefig = matplotlib.figure.Figure.savefig

    def checked(figure, *args, **kwargs):
        result = savefig(figure, *args, **kwargs)
        CROWDED.extend(_crowded_ticks(figure))
        return result

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(matplotlib.figure.Figure, "savefig", checked)
        run(RunContext(inputs=[out / "logs"], out_dir=out, vehicle=load_vehicle("rigid-18t"), dem_dir=out / "dem",
                       options={"cycle": {"n_candidates": 2000}}, say=lambda _m: None))
    return out


def _visible_text(page: str) -> str:
    return re.sub(r"<[^>]+>", " ", re.sub(r"<(script|style)>.*?</(script|style)>", " ", page, flags=re.S))


def _data_drawn(png: bytes) -> float:
    """Share of image columns holding a coloured pixel: axes, text and grid are grey, data is not."""
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    return float(((rgb.max(axis=2) - rgb.min(axis=2)) > 60).any(axis=0).mean())


def test_report_is_self_contained_with_every_chapter(report_dir):
    text = (report_dir / "report.html").read_text()
    for title in ("The drive", "Road gradient", "Vehicle mass per segment", "Representative driving cycle",
                  "Load collectives at the wheel", "The electric truck on this work"):
        assert title in text
    assert not re.search(r"""(src|href)=['"](?!data:)""", text), "the report must not load anything from outside"
    assert not re.search(r"https?://", text), "the report must not name anything to fetch"
    images = re.findall(r"src='data:image/png;base64,([^']+)'", text)
    assert len(images) >= 8
    for payload in images:
        image = Image.open(io.BytesIO(base64.b64decode(payload)))
        assert image.format == "PNG" and image.size[0] > 300 and image.size[1] > 150


def test_report_has_no_nan_text_and_no_empty_figure(report_dir):
    text = (report_dir / "report.html").read_text()
    visible = _visible_text(text)
    assert not re.search(r"\b(nan|inf|infinity)\b", visible, re.I), re.search(r".{60}\b(nan|inf)\b.{20}", visible, re.I)
    for payload in re.findall(r"src='data:image/png;base64,([^']+)'", text):
        assert _data_drawn(base64.b64decode(payload)) > 0.3, "a figure with nothing drawn in it"


def test_no_figure_has_tick_labels_running_together(report_dir):
    assert CROWDED == []


def test_engineer_facing_tables_and_units(report_dir):
    text = _visible_text((report_dir / "report.html").read_text())
    assert "relative_deviation" not in text and "generated vs measured" in text
    assert "damage-equivalent torque range k=" not in text, "the ranges are in their own table, not twice"
    assert "wheel power [kW]" in text and "[W]" not in text
    measured = re.search(r"at the battery, measured drive", text)
    assert measured, "energy per km of the measured drive"
    assert "engine speed" in text and "fuel rate" in text


def test_mass_axis_is_set_by_the_estimates_not_the_estimators_start_values():
    time_s = np.arange(0.0, 600.0, 0.1)
    rls = np.where(time_s < 30, 8800.0, 15_800.0)
    frame = pd.DataFrame({"time_s": time_s, "reported_mass_kg": np.full(len(time_s), 16_500.0)})
    result = SimpleNamespace(segments=[{"mass_ls_kg": 15_790.0, "uncertainty_kg": 330.0}],
                             columns={"mass_rls_kg": rls, "mass_lm_kg": rls})
    low, high = _mass_limits_t(frame, result, None)
    assert 14.0 < low < 15.2 and 16.5 < high < 17.5


def test_a_drive_that_stood_still_says_why_there_is_no_simulation(tmp_path):
    time_s = np.arange(0.0, 600.0, 0.1)
    pd.DataFrame({"time_s": time_s, "speed_mps": np.zeros(len(time_s)), "engine_speed_rpm": 650 + 5 * np.sin(time_s),
                  "fuel_rate_lph": np.full(len(time_s), 2.4)}).to_csv(tmp_path / "idle.csv", index=False)
    run(RunContext(inputs=[tmp_path / "idle.csv"], out_dir=tmp_path / "out", vehicle=load_vehicle("rigid-18t"),
                   say=lambda _m: None))
    text = _visible_text((tmp_path / "out" / "report.html").read_text())
    assert "Not run: the measured drive covers 0.00 km" in text
    assert not re.search(r"\b(nan|inf)\b", text, re.I)
    assert not (tmp_path / "out" / "simulation" / "machine_residence.png").exists()


def _chromium(tmp_path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                           "--disable-background-networking", "--disable-component-update", "--disable-sync",
                           f"--user-data-dir={tmp_path / 'profile'}", *args],
                          check=True, capture_output=True, text=True)


@needs_chromium
def test_report_renders_in_headless_chromium(report_dir, tmp_path):
    shot = tmp_path / "report.png"
    _chromium(tmp_path, "--window-size=1200,6000", f"--screenshot={shot}", (report_dir / "report.html").as_uri())
    image = Image.open(shot).convert("L")
    histogram = image.histogram()
    assert sum(histogram[:250]) > 0.03 * sum(histogram), "the rendered page is (nearly) blank"
    assert len(Image.open(shot).convert("RGB").getcolors(1 << 24)) > 2000, "no figures rendered (too few colours)"


ZOOM_PROBE = """<script>window.addEventListener('load', () => {
  const chart = document.querySelector('.zoom'), canvas = chart.querySelector('canvas');
  const box = canvas.getBoundingClientRect(), before = +chart.dataset.drawn;
  for (let i = 0; i < 5; i++) canvas.dispatchEvent(new WheelEvent('wheel', {deltaY: -100, bubbles: true,
      cancelable: true, clientX: box.left + box.width / 2, clientY: box.top + 10}));
  chart.dataset.zoomed = before + ':' + chart.dataset.drawn;
});</script>"""
"""Five wheel steps into the middle of the chart, as a reader would zoom; notes the points drawn."""


@needs_chromium
def test_the_drive_chart_is_drawn_and_zooms(report_dir, tmp_path):
    page = tmp_path / "probe.html"
    page.write_text((report_dir / "report.html").read_text().replace("</body>", ZOOM_PROBE + "</body>"))
    dom = _chromium(tmp_path, "--virtual-time-budget=5000", "--dump-dom", page.as_uri()).stdout
    zoomed = re.search(r'data-zoomed="(\d+):(\d+)"', dom)
    assert zoomed, "the chart's script did not run"
    before, after = int(zoomed.group(1)), int(zoomed.group(2))
    assert before > 1000, "the whole drive drawn"
    assert 0.2 * before < after < 0.5 * before, "five wheel steps of 0.8 show a third of the drive"
    assert dom.count("<canvas") >= 4
    assert not re.search(r"\b(nan|inf|undefined)\b", _visible_text(dom), re.I)
