"""Logs without the sensors for an estimate still reach a result: a CAN-only CANedge recording
with a known mass (``--mass-kg``) on a road taken as flat (``--flat-road``) gives loads and a cycle,
stated as such; a VECTO ``.vdri`` cycle goes wherever a drive or a cycle to compare does."""

import json
import re

import numpy as np
import pytest

from haulprofile.analysis import cli
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.testing.logs import can_frames, make_truth

asammdf = pytest.importorskip("asammdf")


def run_cli(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def canedge_drive(tmp_path_factory):
    """A CANedge-style MF4 (``CAN_DataFrame.*`` channels, as the real recordings in tests/data) of
    a 10-minute drive's J1939 traffic: wheel speed and engine data, no GPS, no barometer."""
    rng = np.random.default_rng(27)
    frames = can_frames(make_truth(6000, rng), filler_hz=0.0, rng=rng)
    t = (frames["t_mono_ns"] - frames["t_mono_ns"][0]) / 1e9
    data = np.stack([np.frombuffer(bytes(d), np.uint8) for d in frames["data"]])
    mdf = asammdf.MDF(version="4.10")
    mdf.append([asammdf.Signal(frames["arbitration_id"].astype(np.uint32), t, name="CAN_DataFrame.ID"),
                asammdf.Signal(data, t, name="CAN_DataFrame.DataBytes"),
                asammdf.Signal(np.full(len(t), 8, np.uint8), t, name="CAN_DataFrame.DLC"),
                asammdf.Signal(np.ones(len(t), np.uint8), t, name="CAN_DataFrame.IDE")])
    path = mdf.save(tmp_path_factory.mktemp("canedge") / "00000001.mf4", overwrite=True)
    mdf.close()
    return path


def test_a_can_only_log_with_a_known_mass_on_a_flat_road_gives_loads_and_a_cycle(canedge_drive, tmp_path, capsys):
    out = tmp_path / "out"
    code, _, err = run_cli(capsys, "run", canedge_drive, "--vehicle", "rigid-18t", "--mass-kg", 19_500, "--flat-road",
                           "--out", out, "--candidates", 300, "--cycle-duration", 300)
    assert code in (0, 3), err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["gradient"]["method"] == "flat_road" and summary["mass"]["given_mass_kg"] == 19_500
    assert "loads" in summary and summary["loads"]["measured"]["rainflow_cycles"] > 0
    assert "cycle" in summary and (out / "cycle.vdri").is_file()
    assert "cycle" not in summary.get("skipped", {}) and "mass" not in summary.get("skipped", {})
    report = (out / "report.html").read_text()
    assert "taken as flat, not estimated" in report and "given, not estimated" in report


def test_without_them_the_same_log_says_which_flag_would_carry_it(canedge_drive, tmp_path, capsys):
    code, _, err = run_cli(capsys, "run", canedge_drive, "--vehicle", "rigid-18t", "--out", tmp_path / "out",
                           "--candidates", 300, "--cycle-duration", 300)
    assert code == 3
    assert "cycle stage was skipped" in err and "give --flat-road and --mass-kg KG" in err, err


def test_the_real_canedge_recording_stands_still_and_says_so(data_dir, tmp_path, capsys):
    out = tmp_path / "out"
    code, _, err = run_cli(capsys, "run", data_dir / "real-can" / "css-j1939-tp-186s.MF4", "--vehicle", "rigid-18t",
                           "--mass-kg", 20_000, "--flat-road", "--out", out, "--candidates", 300)
    assert code == 3 and "stands still throughout" in err, err
    summary = json.loads((out / "summary.json").read_text())
    assert "loads" in summary and summary["mass"]["given_mass_kg"] == 20_000


def test_analyze_loads_on_a_trace_with_a_known_mass_and_a_vecto_cycle(data_dir, canedge_drive, tmp_path, capsys):
    code, _, err = run_cli(capsys, "signals", canedge_drive, "--out", tmp_path / "trace.csv")
    assert code == 0, err
    code, _, err = run_cli(capsys, "loads", tmp_path / "trace.csv", "--vehicle", "rigid-18t", "--out", tmp_path / "l0")
    assert code == 2 and "--mass-kg" in err and "--flat-road" in err, err
    code, out, err = run_cli(capsys, "loads", tmp_path / "trace.csv", "--vehicle", "rigid-18t", "--mass-kg", 19_500,
                             "--flat-road", "--cycle", data_dir / "vecto-cycles" / "Interurban.vdri",
                             "--out", tmp_path / "l1")
    assert code == 0, err
    assert "measured:" in out and "generated:" in out and (tmp_path / "l1" / "comparison.csv").is_file()


def test_a_vecto_cycle_is_a_drive_for_info_and_run(data_dir, tmp_path, capsys):
    cycle = data_dir / "vecto-cycles" / "Interurban.vdri"
    code, out, err = run_cli(capsys, "info", cycle)
    assert code == 0 and "speed_mps" in out and "gradient_pct" in out, err
    code, _, err = run_cli(capsys, "run", cycle, "--vehicle", "rigid-18t", "--mass-kg", 16_000, "--out",
                           tmp_path / "out", "--candidates", 300, "--cycle-duration", 600)
    assert code in (0, 3), err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert {"cycle", "loads", "simulation"} <= set(summary)
    from haulprofile.analysis.design.synthesis import HARDEST
    assert summary["design"]["cycles"] == ["generated cycle", HARDEST], "124 km of drive: its hardest stretch sizes"


def test_a_fleet_of_can_only_logs_with_a_known_mass_gets_its_cycle(canedge_drive, tmp_path, capsys):
    logs = tmp_path / "truck"
    logs.mkdir()
    (logs / canedge_drive.name).write_bytes(canedge_drive.read_bytes())
    code, _, err = run_cli(capsys, "fleet", logs, "--vehicle", "rigid-18t", "--mass-kg", 19_500, "--flat-road",
                           "--workers", 1, "--candidates", 300, "--cycle-duration", 300, "--out", tmp_path / "out")
    assert code in (0, 3), err
    assert " failed: " not in err, err  # no log failed (an invalid cycle may be said)
    assert (tmp_path / "out" / "truck" / "cycle.vdri").is_file()
    page = (tmp_path / "out" / "fleet-report.html").read_text()
    visible = re.sub(r"<[^>]+>", " ", re.sub(r"<(script|style)[^>]*>.*?</(script|style)>", " ", page, flags=re.S))
    assert "Truck truck" in visible and "19.5 (given)" in visible and "km/day" in visible
    assert not re.search(r"\b(nan|inf)\b", visible, re.I)
    assert not re.search(r"\b[a-z]{2,}[a-z0-9]*_[a-z0-9_]+\b", visible), "no raw field names"
    per_km = float(re.search(r"<b>([0-9.]+) kWh/km</b>battery on the cycle", page).group(1))
    range_km = float(re.search(r"<b>([0-9]+) km</b>range on the cycle", page).group(1))
    battery = load_vehicle("rigid-18t").electric_powertrain
    usable = battery.battery_capacity_kwh * (battery.initial_soc - battery.min_soc)
    assert abs(range_km - usable / per_km) <= 1 + 0.002 * range_km, "range = usable battery energy / energy per km"
    operation = json.loads((tmp_path / "out" / "truck" / "fleet-summary.json").read_text())["operation"]
    assert f"{operation['cycle_battery_kwh_per_km']:.3f}" == f"{per_km:.3f}"
    assert f"{operation['range_km']:.0f}" == f"{range_km:.0f}", "the report's numbers are the summary's"


@pytest.mark.parametrize("command", ["gradient", "mass"])
def test_a_vecto_cycle_where_it_makes_no_sense_is_one_clear_line(data_dir, tmp_path, capsys, command):
    code, _, err = run_cli(capsys, command, data_dir / "vecto-cycles" / "Coach.vdri", "--vehicle", "rigid-18t",
                           "--out", tmp_path / "out") if command == "mass" else \
        run_cli(capsys, command, data_dir / "vecto-cycles" / "Coach.vdri", "--out", tmp_path / "out")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "VECTO cycle" in err and "analyze run" in err, err
