"""The report: self-contained, every chapter present with its figures, every image a real PNG."""

import base64
import io
import re
import shutil
import subprocess

import pytest
from PIL import Image

from haulprofile.analysis.pipeline import RunContext, run
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.analysis.virtual_truck import drive, load_scenario, write_dem, write_mcap


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    scenario = load_scenario("regional-tunnel")
    truck = drive(scenario, load_vehicle("rigid-18t"), seed=3)
    write_dem(truck, out / "dem")
    write_mcap(truck, out / "logs" / "drive.mcap")
    run(RunContext(inputs=[out / "logs"], out_dir=out, vehicle=load_vehicle("rigid-18t"), dem_dir=out / "dem",
                   options={"cycle": {"n_candidates": 2000}}, say=lambda _m: None))
    return out


def test_report_is_self_contained_with_every_chapter(report_dir):
    text = (report_dir / "report.html").read_text()
    for title in ("The drive", "Road gradient", "Vehicle mass per segment", "Representative driving cycle",
                  "Load collectives at the wheel", "The electric truck on this work"):
        assert title in text
    assert not re.search(r"""(src|href)=['"](?!data:)""", text), "the report must not load anything from outside"
    images = re.findall(r"src='data:image/png;base64,([^']+)'", text)
    assert len(images) >= 8
    for payload in images:
        image = Image.open(io.BytesIO(base64.b64decode(payload)))
        assert image.format == "PNG" and image.size[0] > 300 and image.size[1] > 150


@pytest.mark.skipif(shutil.which("chromium") is None, reason="headless Chromium not installed (Debian package chromium)")
def test_report_renders_in_headless_chromium(report_dir, tmp_path):
    shot = tmp_path / "report.png"
    subprocess.run(["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                    "--disable-background-networking", "--disable-component-update", "--disable-sync",
                    f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1200,6000",
                    f"--screenshot={shot}", (report_dir / "report.html").as_uri()],
                   check=True, capture_output=True, timeout=120)
    image = Image.open(shot).convert("L")
    histogram = image.histogram()
    print(f"non-white share {sum(histogram[:250]) / sum(histogram):.3f}, colours {len(Image.open(shot).getcolors(1 << 24))}")
    assert sum(histogram[:250]) > 0.03 * sum(histogram), "the rendered page is (nearly) blank"
    assert len(Image.open(shot).convert("RGB").getcolors(1 << 24)) > 2000, "no figures rendered (too few colours)"
