"""One rule for every output: a command writes only what it names, only inside the folder it was
given, and replaces or removes only files it wrote itself (`analysis.manifest`); symbolic links
are refused, not followed. Each test is a way users' logs were lost before."""

import os
import shutil
from dataclasses import replace

import pytest

from haulprofile.analysis import pipeline
from haulprofile.analysis.cli import main
from haulprofile.analysis.errors import UserError
from haulprofile.analysis.pipeline import RunContext, run
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.testing.drives import synthetic_drive

CYCLE = {"n_candidates": 200, "duration_s": 300.0}
LOG = b"\x89MCAP0\r\n" + b"a user's log" * 100


@pytest.fixture
def quick_stages(monkeypatch):
    """Kinematics, cycle, loads and simulation: every folder of a run, in seconds."""
    monkeypatch.setattr(pipeline, "STAGES", [s for s in pipeline.STAGES
                                             if s.name in ("kinematics", "cycle", "loads", "simulation")])


def drive_table(path):
    path.parent.mkdir(parents=True, exist_ok=True)
    synthetic_drive(1200, seed=4).round(3).drop(columns=["distance_m"]).to_csv(path, index=False)
    return path


def quick_run(inputs, out, seed=1):
    return run(RunContext(inputs=inputs, out_dir=out, vehicle=load_vehicle("rigid-18t"),
                          options={"cycle": {**CYCLE, "seed": seed}}, say=lambda _m: None))


def test_a_run_into_folders_holding_logs_keeps_them_and_the_input(quick_stages, tmp_path):
    out = tmp_path / "O"
    table = drive_table(out / "loads" / "t.csv")
    (out / "cycles").mkdir()
    (out / "cycles" / "k.mcap").write_bytes(LOG)
    (out / "simulation").mkdir()
    (out / "simulation" / "notes.txt").write_text("mine")
    before = table.read_bytes()
    for seed in (1, 2):  # the rerun removes and replaces its own files, never these
        quick_run([table], out, seed)
    assert table.read_bytes() == before
    assert (out / "cycles" / "k.mcap").read_bytes() == LOG
    assert (out / "simulation" / "notes.txt").read_text() == "mine"
    assert (out / "loads" / "comparison.csv").is_file() and (out / "simulation" / "summary.json").is_file()


def test_a_full_run_removes_only_its_own_earlier_files(quick_stages, tmp_path, monkeypatch):
    out = tmp_path / "out"
    table = drive_table(tmp_path / "drive.csv")
    quick_run([table], out)
    (out / "loads" / "mine.csv").write_text("a user's table")

    def skipped(ctx):
        ctx.skip("this stage", "not this time")

    monkeypatch.setattr(pipeline, "STAGES", [replace(s, run=skipped) if s.name != "kinematics" else s
                                             for s in pipeline.STAGES])
    run(RunContext(inputs=[table], out_dir=out, vehicle=load_vehicle("rigid-18t"), say=lambda _m: None))
    assert not (out / "cycle.csv").exists() and not (out / "loads" / "comparison.csv").exists()
    assert (out / "loads" / "mine.csv").read_text() == "a user's table"
    assert not (out / "simulation").exists()  # made by the first run, left empty: gone


def test_a_file_the_user_put_where_a_run_writes_is_refused_before_any_stage(quick_stages, tmp_path):
    out = tmp_path / "out"
    table = drive_table(tmp_path / "drive.csv")
    out.mkdir()
    (out / "report.html").write_text("the user's own report")
    with pytest.raises(UserError, match="did not write"):
        quick_run([table], out)
    assert (out / "report.html").read_text() == "the user's own report"


def test_a_file_copied_over_one_the_run_wrote_is_no_longer_its_own(quick_stages, tmp_path):
    out = tmp_path / "out"
    table = drive_table(tmp_path / "drive.csv")
    quick_run([table], out)
    (out / "cycle.csv").unlink()
    (out / "cycle.csv").write_text("the user's cycle")
    with pytest.raises(UserError, match="did not write"):
        quick_run([table], out, seed=2)
    assert (out / "cycle.csv").read_text() == "the user's cycle"


def test_a_symbolic_link_in_the_output_is_refused_not_followed(quick_stages, tmp_path):
    out = tmp_path / "out"
    table = drive_table(tmp_path / "drive.csv")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out.mkdir()
    (out / "loads").symlink_to(elsewhere)
    with pytest.raises(UserError, match="symbolic link"):
        quick_run([table], out)
    assert not list(elsewhere.iterdir())


def test_demo_keeps_a_users_log_in_its_logs_folder(tmp_path):
    from test_demo import SCENARIO

    (tmp_path / "short.toml").write_text(SCENARIO)
    out = tmp_path / "DIR"
    (out / "logs").mkdir(parents=True)
    (out / "logs" / "truck07.mcap").write_bytes(LOG)
    argv = ["demo", "--out", str(out), "--scenario", str(tmp_path / "short.toml"), "--realism", "ideal",
            "--direct", "--design-population", "8", "--design-generations", "2", "--quiet"]
    for seed in ("1", "2"):
        assert main(argv + ["--seed", seed]) in (0, 3)
    assert (out / "logs" / "truck07.mcap").read_bytes() == LOG
    demo_logs = [p.name for p in (out / "logs").iterdir() if p.name != "truck07.mcap"]
    assert len(demo_logs) == 1 and demo_logs[0].endswith("-seed2.mcap"), "its own earlier log replaced"


def test_demo_through_the_daemon_keeps_a_users_log(tmp_path, monkeypatch):
    """The daemon's path (its recorder replaced by the direct writer, the logging itself is
    `test_demo`'s) once removed every ``logs/*.mcap`` before logging."""
    from haulprofile.analysis.virtual_truck import write_mcap
    from haulprofile.logger import emulators
    from test_demo import SCENARIO

    def recorded(streams, out_dir, **_kwargs):
        return write_mcap(virtual_drives[-1], out_dir / "haulprofile_test.mcap")

    from haulprofile.analysis.commands import demo as demo_command

    virtual_drives = []
    real_drive = demo_command.drive
    monkeypatch.setattr(demo_command, "drive", lambda *a, **k: virtual_drives.append(real_drive(*a, **k)) or
                        virtual_drives[-1])
    monkeypatch.setattr(emulators, "record_streams", recorded)
    (tmp_path / "short.toml").write_text(SCENARIO)
    out = tmp_path / "DIR"
    (out / "logs").mkdir(parents=True)
    (out / "logs" / "truck07.mcap").write_bytes(LOG)
    assert main(["demo", "--out", str(out), "--scenario", str(tmp_path / "short.toml"), "--realism", "ideal",
                 "--no-warmup", "--design-population", "8", "--design-generations", "2", "--quiet"]) in (0, 3)
    assert (out / "logs" / "truck07.mcap").read_bytes() == LOG


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    from haulprofile.analysis.virtual_truck import drive, load_scenario, write_mcap
    from test_demo import SCENARIO

    root = tmp_path_factory.mktemp("short")
    (root / "short.toml").write_text(SCENARIO)
    log = write_mcap(drive(load_scenario(root / "short.toml"), seed=1), root / "logs" / "short.mcap")
    (root / "zones.toml").write_text('[[zones]]\nname = "depot"\nlat = 0.0\nlon = 0.0\nradius_m = 500\n')
    return log, root / "zones.toml"


def test_redact_never_replaces_a_different_log_of_the_same_name(short_log, tmp_path, capsys):
    log, zones = short_log
    out = tmp_path / "D"
    out.mkdir()
    (out / "short.mcap").write_bytes(LOG)
    assert main(["redact", str(log), "--zones", str(zones), "--out", str(out)]) == 2
    assert "did not write" in capsys.readouterr().err
    assert (out / "short.mcap").read_bytes() == LOG


def test_redact_replaces_its_own_copy_and_writes_through_no_link(short_log, tmp_path):
    log, zones = short_log
    out = tmp_path / "D"
    out.mkdir()
    other = tmp_path / "other.mcap"
    other.write_bytes(LOG)
    (out / "short.mcap.partial").symlink_to(other)
    for _ in range(2):
        assert main(["redact", str(log), "--zones", str(zones), "--out", str(out)]) == 0
    assert other.read_bytes() == LOG
    assert (out / "short.mcap").read_bytes()[:8] == LOG[:8] and (out / "short.mcap").stat().st_size > 10_000
    assert (out / "short.mcap").stat().st_mode & 0o777 == 0o640


def test_recover_refuses_a_dangling_link_and_writes_0640(short_log, tmp_path, capsys):
    log, _ = short_log
    link = tmp_path / "repaired.mcap"
    link.symlink_to(tmp_path / "elsewhere.mcap")
    assert main(["recover", str(log), "-o", str(link)]) == 2
    assert "symbolic link" in capsys.readouterr().err and not (tmp_path / "elsewhere.mcap").exists()
    old = os.umask(0o022)
    try:
        assert main(["recover", str(log), "-o", str(tmp_path / "fresh.mcap")]) == 0
    finally:
        os.umask(old)
    assert (tmp_path / "fresh.mcap").stat().st_mode & 0o777 == 0o640
