"""``analyze demo``: virtual truck → DEM tiles + MCAP log → the pipeline, with one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from mcap.reader import make_reader

from haulprofile.analysis.cli import main
from haulprofile.analysis.dem.srtm import SrtmDem

SCENARIO = """
[scenario]
name = "demo-short"
vehicle = "rigid-18t"
start_latitude_deg = 47.42
start_longitude_deg = 8.47
start_heading_deg = 70.0
start_time = 2025-05-14T06:30:00Z

[route]
[[route.section]]
length_m = 2000
speed_kmh = 60
stop_s = 60

[[route.section]]
length_m = 2500
speed_kmh = 70

[[tunnel]]
start_m = 2600.0
length_m = 900.0

[payload]
initial_kg = 6000.0
after_stop_kg = [2000.0]
"""


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    root = tmp_path_factory.mktemp("demo")
    (root / "short.toml").write_text(SCENARIO)
    code = main(["demo", "--out", str(root / "out"), "--scenario", str(root / "short.toml"), "--seed", "5",
                 "--realism", "ideal", "--design-population", "16", "--design-generations", "4", "--quiet"])
    return code, root / "out"


def test_demo_writes_log_dem_truth_and_analysis(demo):
    code, out = demo
    assert code == 0
    logs = sorted((out / "logs").glob("*.mcap"))
    assert len(logs) == 1 and logs[0].name.startswith("haulprofile_"), "logged by the daemon"
    with open(logs[0], "rb") as stream:
        topics = {channel.topic for channel in make_reader(stream).get_summary().channels.values()}
    assert {"/can/frames", "/imu", "/gps/fix", "/barometer", "/time/sync"} <= topics
    truth = pd.read_parquet(out / "truth.parquet")
    dem = SrtmDem(out / "dem").height_m(truth["latitude_deg"], truth["longitude_deg"])
    assert np.max(np.abs(dem - truth["terrain_height_m"])) < 2.0
    assert (out / "summary.json").is_file() and (out / "signals.parquet").is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert "ingest" in summary["stages"]
    signals = pd.read_parquet(out / "signals.parquet")
    # the daemon's clock starts when it does, not with the drive: align at the first departure
    offset = (signals["time_s"][signals["speed_mps"] > 1.0].iloc[0] - truth["time_s"][truth["speed_mps"] > 1.0].iloc[0])
    speed = np.interp(signals["time_s"] - offset, truth["time_s"], truth["speed_mps"])
    assert np.nanmedian(np.abs(signals["speed_mps"] - speed)) < 0.1


def test_demo_prints_one_line_for_a_bad_scenario(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(SCENARIO.replace("speed_kmh = 60", "speed_kmh = 60\nlanes = 2"))
    code = main(["demo", "--out", str(tmp_path / "out"), "--scenario", str(path)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and "unknown key 'lanes'" in err


def test_demo_logs_at_least_twice_as_fast_as_20x_with_fifos_that_keep_up():
    """The default speed-up halves the logging phase of 20x; at it every FIFO sensor holds at
    least 50 ms of real time and the ECU has 50 ms of real time to answer OBD-II (arithmetic on
    the configuration, not a timing)."""
    import argparse

    from haulprofile.analysis.commands import demo as demo_command
    from haulprofile.logger.emulators.compression import compressed_config

    parser = argparse.ArgumentParser()
    demo_command.add_arguments(parser)
    scale = parser.parse_args([]).time_scale
    assert scale >= 40.0
    config = compressed_config(scale)
    fifo_depth = 32  # LPS25HB and LSM9DS1 datasheets
    for odr_hz in (config.i2c.lps25hb.odr_hz, config.i2c.lsm9ds1.odr_hz):
        assert fifo_depth / odr_hz / scale >= 0.05
    assert config.can.obd.timeout_s / scale >= 0.05


def test_demo_progress_line():
    from haulprofile.analysis.commands.demo import progress_line
    from haulprofile.logger.emulators.rig import Progress

    assert progress_line(Progress(192.0, 2298.0, 48000)) == "  logging: 3.2 of 38.3 min driven, 48 000 CAN frames"
