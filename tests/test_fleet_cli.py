"""``analyze fleet`` as a user meets it: outputs, exit codes, and one line per kind of bad input."""

import json

import numpy as np
import pytest

from haulprofile.analysis.cli import main
from haulprofile.testing.drives import synthetic_drive


def write_table(path, seed: int, duration_s: float = 900.0):
    frame = synthetic_drive(duration_s, seed=seed, kind="regional")
    frame["accel_mps2"] = np.gradient(frame["speed_mps"].to_numpy(), frame["time_s"].to_numpy())
    path.parent.mkdir(parents=True, exist_ok=True)
    frame.to_parquet(path)


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli")
    for seed in (0, 1):
        write_table(root / "group-a" / f"drive-{seed}.parquet", seed)
    write_table(root / "group-b" / "day-1" / "drive.parquet", 7)
    return root


def run_cli(capsys, *argv):
    code = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def test_two_groups_two_vehicles(tables, tmp_path, capsys):
    code, out, err = run_cli(capsys, "fleet", tables / "group-a", tables / "group-b", "--vehicle", "rigid-18t",
                             "--vehicle", "tractor-40t", "--out", tmp_path, "--workers", "1", "--candidates", "200",
                             "--duration", "600", "--json")
    assert code in (0, 3), err
    summary = json.loads(out)
    assert [g["group"] for g in summary["groups"]] == ["group-a", "group-b"]
    assert [g["logs"] for g in summary["groups"]] == [2, 1]
    group_b = json.loads((tmp_path / "group-b" / "fleet-summary.json").read_text())
    assert group_b["vehicle"].startswith("Tractor") or "40" in group_b["vehicle"]
    assert (tmp_path / "group-b" / "cycle.vdri").is_file()


def test_no_figures_gives_the_same_cycle(tables, tmp_path, capsys):
    cycles = []
    for flag in ([], ["--no-figures"]):
        out = tmp_path / ("without" if flag else "with")
        code, _, err = run_cli(capsys, "fleet", tables / "group-a", "--vehicle", "rigid-18t", "--out", out,
                               "--workers", "1", "--candidates", "200", "--duration", "600", "--quiet", *flag)
        assert code in (0, 3), err
        cycles.append((out / "group-a" / "cycle.vdri").read_text())
    assert cycles[0] == cycles[1]


def test_a_failing_log_is_named_and_the_others_go_on(tables, tmp_path, capsys):
    group = tmp_path / "group"
    write_table(group / "good.parquet", 3)
    (group / "broken.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    code, out, err = run_cli(capsys, "fleet", group, "--vehicle", "rigid-18t", "--out", tmp_path / "out",
                             "--workers", "1", "--candidates", "200", "--duration", "600", "--quiet")
    assert code == 3
    assert "broken.mcap" in err and "Traceback" not in err
    summary = json.loads((tmp_path / "out" / "group" / "fleet-summary.json").read_text())
    assert summary["failed"][0]["log"].endswith("broken.mcap") and len(summary["logs"]) == 1
    assert (tmp_path / "out" / "group" / "cycle.csv").is_file()
    said = (tmp_path / "out" / "group" / "logs" / "broken.mcap" / "messages.txt").read_text()
    assert "FAILED" in said and "broken.mcap" in said


def test_all_logs_failing_is_an_error(tmp_path, capsys):
    group = tmp_path / "group"
    group.mkdir()
    (group / "a.mcap").write_bytes(b"not an mcap file at all")
    code, _, err = run_cli(capsys, "fleet", group, "--vehicle", "rigid-18t", "--out", tmp_path / "out",
                           "--workers", "1")
    assert code == 2
    line = one_line_error(err)
    assert "all 1 logs failed" in line and "a.mcap" in line


def test_empty_log_directory(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    code, _, err = run_cli(capsys, "fleet", tmp_path / "empty", "--vehicle", "rigid-18t", "--out", tmp_path / "out")
    assert code == 2
    assert "empty: no logs" in one_line_error(err)


def test_missing_log_directory(tmp_path, capsys):
    code, _, err = run_cli(capsys, "fleet", tmp_path / "nowhere", "--vehicle", "rigid-18t", "--out", tmp_path / "o")
    assert code == 2
    assert "not found" in one_line_error(err)


def test_vehicle_count_mismatch(tables, tmp_path, capsys):
    code, _, err = run_cli(capsys, "fleet", tables / "group-a", tables / "group-b", tables / "group-a",
                           "--vehicle", "rigid-18t", "--vehicle", "tractor-40t", "--out", tmp_path)
    assert code == 2
    assert "2 vehicle files for 3 log directories" in one_line_error(err)


def test_vehicle_file_typo(tables, tmp_path, capsys):
    code, _, err = run_cli(capsys, "fleet", tables / "group-a", "--vehicle", "rigid-18", "--out", tmp_path)
    assert code == 2
    assert "rigid-18" in one_line_error(err)


def test_workers_must_be_positive(tables, tmp_path, capsys):
    code, _, err = run_cli(capsys, "fleet", tables / "group-a", "--vehicle", "rigid-18t", "--out", tmp_path,
                           "--workers", "0")
    assert code == 2
    assert "--workers" in one_line_error(err)


def test_unreachable_scheduler(tables, tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    import socket

    from haulprofile.analysis.fleet import runner

    monkeypatch.setattr(runner, "DASK_CONNECT_TIMEOUT", "1s")
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    code, _, err = run_cli(capsys, "fleet", tables / "group-a", "--vehicle", "rigid-18t", "--out", tmp_path,
                           "--scheduler", f"tcp://127.0.0.1:{port}")
    assert code == 2
    assert "cannot reach the Dask scheduler" in one_line_error(err)


def test_speed_only_table_gives_totals_and_says_what_is_missing(tmp_path, capsys):
    import pandas as pd

    group = tmp_path / "group"
    group.mkdir()
    time_s = np.arange(0.0, 600.0, 0.1)
    pd.DataFrame({"time_s": time_s, "speed_mps": 10.0 + 5.0 * np.sin(time_s / 60.0)}).to_parquet(group / "a.parquet")
    write_table(group / "b.parquet", 4)
    out = group / "out"
    code, printed, err = run_cli(capsys, "fleet", group, "--vehicle", "rigid-18t", "--out", out, "--workers", "1",
                                 "--candidates", "200", "--duration", "600")
    assert code in (0, 3), err
    assert "a.parquet: no transition counts" in printed and "no wheel loads" in printed
    summary = json.loads((out / "group" / "fleet-summary.json").read_text())
    assert len(summary["logs"]) == 2 and summary["totals"]["distance_km"] > 5.9
    # a rerun does not take the first run's tables (inside LOGDIR) for logs
    code, printed, err = run_cli(capsys, "fleet", group, "--vehicle", "rigid-18t", "--out", out, "--workers", "1",
                                 "--candidates", "200", "--duration", "600", "--json")
    assert [g["logs"] for g in json.loads(printed)["groups"]] == [2]


def test_groups_of_the_same_directory_name_get_distinct_names(tmp_path):
    from haulprofile.analysis.fleet import FleetSpec
    from haulprofile.analysis.vehicle import load_vehicle

    for parent in ("a", "b"):
        write_table(tmp_path / parent / "logs" / "drive.parquet", 1, 120.0)
    spec = FleetSpec.of([tmp_path / "a" / "logs", tmp_path / "b" / "logs"], [load_vehicle("rigid-18t")],
                        dem_dir=str(tmp_path))
    assert [g.name for g in spec.groups] == ["logs", "logs-2"]
    assert spec.dem_dir == tmp_path


def test_copies_of_a_log_count_once(tmp_path, capsys):
    """Three copies of one drive in a group's directory: one log in the totals, two warnings."""
    import shutil

    write_table(tmp_path / "group" / "drive.parquet", 3, duration_s=600.0)
    for name in ("copy-1.parquet", "copy-2.parquet"):
        shutil.copy(tmp_path / "group" / "drive.parquet", tmp_path / "group" / name)
    code, out, err = run_cli(capsys, "fleet", tmp_path / "group", "--vehicle", "rigid-18t", "--out", tmp_path / "out",
                             "--workers", "1", "--candidates", "50", "--cycle-duration", "300", "--json")
    assert code in (0, 3), err
    (group,) = json.loads(out)["groups"]
    import pandas as pd

    time = pd.read_parquet(tmp_path / "group" / "drive.parquet")["time_s"]
    assert group["logs"] == 1 and group["totals"]["duration_s"] == pytest.approx(time.iloc[-1] - time.iloc[0])
    assert err.count("same content") == 2
