"""GPS-only logs: raw NMEA and UBX receiver output recognised by content (tests/data/real-gps: real
u-blox and Trimble streams) and read into the signals table, speed from the receiver when there is
no CAN; a virtual truck's drive as the NMEA its receiver would send, through info, signals and run."""

import datetime as dt
import io
import math

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.cli import main
from haulprofile.analysis.ingest import foreign, ingest_logs
from haulprofile.analysis.ingest.gnss import read_fixes
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.analysis.virtual_truck import drive, load_scenario
from haulprofile.logger.emulators.gps import epoch_sentences
from haulprofile.analysis.kinematics import distance_m

WITH_FIXES = ["pyubx2-pygpsdata-MIXED.log", "pyubx2-pygpsdata-MIXED2.log", "pynmeagps-pygpsdata-nmea2.log",
              "pynmeagps-pygpsdata-nmea4.log", "pynmeagps-pygpsdata-mixed.log", "pyubx2-pygpsdata-BADCK2.log",
              "pyubx2-pygpsdata-NMEA.log"]
NO_SPEED = {"pynmeagps-pygpsdata-mixed.log", "pyubx2-pygpsdata-NMEA.log"}
"""Their standard sentences give a position (GGA) but no speed (no RMC or VTG with a fix)."""
WITHOUT_FIX = ["pynmeagps-trimble_nmea.log", "pynmeagps-pygpsdata-nmeastartup.log",
               "pynmeagps-pygpsdata-nmeabadck.log", "pyubx2-pygpsdata-NMEABADEND.log"]


@pytest.mark.parametrize("name", WITH_FIXES + WITHOUT_FIX)
def test_receiver_logs_are_told_apart_from_can_logs_by_content(data_dir, name):
    assert foreign.kind(data_dir / "real-gps" / name) == "gnss"


def test_can_logs_keep_their_kind(data_dir, tmp_path):
    candump = tmp_path / "bus.log"
    candump.write_text("(1436509052.249713) vcan0 18FEF100#FF0A14FFFFFFFFFF\n"
                       "(1436509052.349713) vcan0 18FEF100#FF0B14FFFFFFFFFF\n")
    assert foreign.kind(candump) == "can"
    assert foreign.kind(data_dir / "real-can" / "css-j1939-tp-186s.MF4") == "mf4"


@pytest.mark.parametrize("name", WITH_FIXES)
def test_analyze_info_reads_a_gps_only_log(data_dir, name, capsys):
    assert main(["info", str(data_dir / "real-gps" / name)]) == 0
    out = capsys.readouterr().out
    assert "gps:latitude" in out
    if name not in NO_SPEED:
        assert "gps:speed_mps" in out


@pytest.mark.parametrize("name", WITHOUT_FIX)
def test_a_gps_log_without_a_fix_is_a_one_line_error(data_dir, name, capsys):
    assert main(["info", str(data_dir / "real-gps" / name)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "without a single position fix" in err[0]


def test_ubx_nav_pvt_log_gives_its_fixes_and_utc(data_dir):
    pyubx2 = pytest.importorskip("pyubx2")
    path = data_dir / "real-gps" / "pyubx2-pygpsdata-MIXED.log"
    reference = [m for _, m in pyubx2.UBXReader(io.BytesIO(path.read_bytes()), protfilter=pyubx2.UBX_PROTOCOL,
                                                   quitonerror=0) if m is not None and m.identity == "NAV-PVT"]
    fixes = read_fixes(path)
    assert len(fixes) == len(reference) == 39
    assert fixes[0]["latitude"] == pytest.approx(reference[0].lat) and fixes[0]["h_acc_m"] == reference[0].hAcc / 1000
    table, summary = ingest_logs([path])
    first = dt.datetime(2020, 10, 23, 11, 33, 15, tzinfo=dt.timezone.utc).timestamp() * 1e9
    assert table["wall_time_ns"].iloc[0] == pytest.approx(first, abs=1e8)
    assert summary["sources"]["speed_mps"]["source"] == "gps"
    assert table["speed_mps"].max() == pytest.approx(max(m.gSpeed for m in reference) / 1000)


@pytest.fixture(scope="module")
def nmea_drive(tmp_path_factory):
    """The first 20 minutes of a virtual truck's drive as its receiver's NMEA (RMC, VTG, GGA, GSA,
    GST at 1 Hz), with the truck's true speed."""
    truck = drive(load_scenario("regional-tunnel"), load_vehicle("rigid-18t"), seed=3)
    gps = truck.sensors["gps"]
    gps = gps[gps["time_s"] < 1200]
    start = dt.datetime(2024, 5, 14, 23, 50, 0)  # through midnight: the date changes in RMC
    lines = []
    for row in gps.itertuples(index=False):
        values = row._asdict()
        values["course_deg"] = 0.0
        lines += epoch_sentences(start + dt.timedelta(seconds=row.time_s), values)
    path = tmp_path_factory.mktemp("gnss") / "receiver.nmea"
    path.write_text("\r\n".join(lines) + "\r\n")
    return path, gps, truck.states


def test_speed_and_distance_of_a_gps_only_drive(nmea_drive):
    path, gps, states = nmea_drive
    table, summary = ingest_logs([path])  # 10 Hz: the 1 Hz fixes' speeds are joined linearly
    fixed = gps[gps["fix_quality"] > 0]
    assert summary["sources"]["speed_mps"]["key"] == "gps:speed_mps"
    assert len(read_fixes(path)) == len(fixed)
    assert table["time_s"].iloc[-1] == pytest.approx(fixed["time_s"].iloc[-1] - fixed["time_s"].iloc[0], abs=1.0)
    truth = np.interp(table["time_s"] + fixed["time_s"].iloc[0], states["time_s"], states["speed_mps"])
    moving = np.isfinite(table["speed_mps"])
    assert np.median(np.abs(table["speed_mps"][moving] - truth[moving])) < 0.035  # held between fixes: 0.042
    true_distance = np.interp(fixed["time_s"].iloc[-1], states["time_s"], states["distance_m"]) - \
        np.interp(fixed["time_s"].iloc[0], states["time_s"], states["distance_m"])
    assert distance_m(table["time_s"], table["speed_mps"])[-1] == pytest.approx(true_distance, rel=0.03)
    midnight = dt.datetime(2024, 5, 15, tzinfo=dt.timezone.utc).timestamp() * 1e9
    assert table["wall_time_ns"].iloc[0] < midnight < table["wall_time_ns"].iloc[-1]


def test_signals_and_run_on_a_gps_only_drive(nmea_drive, tmp_path):
    path, _, _ = nmea_drive
    assert main(["signals", str(path), "-o", str(tmp_path / "signals.parquet")]) == 0
    signals = pd.read_parquet(tmp_path / "signals.parquet")
    assert {"speed_mps", "latitude_deg", "gps_altitude_m"} <= set(signals.columns)
    code = main(["run", str(path), "--vehicle", "rigid-18t", "--out", str(tmp_path / "run"), "--design-population", "16",
                 "--design-generations", "4", "--quiet"])
    assert code in (0, 3)
    summary = pd.read_json(tmp_path / "run" / "summary.json", typ="series")
    assert summary["ingest"]["sources"]["speed_mps"]["source"] == "gps"
    assert (tmp_path / "run" / "report.html").is_file()
    assert math.isfinite(summary["simulation"]["battery_kwh_per_km"])
