"""File modes under a shell's umask (0022) where they were 0644/0755 before: the logger's preflight,
a fleet's outputs, the stage cache of a run that failed; and zone polygons that cannot be zones."""

from __future__ import annotations

import os
import stat

import pytest

from haulprofile.analysis import pipeline
from haulprofile.analysis.pipeline import RunContext, run
from haulprofile.contract.privacy import zones_from_tables
from haulprofile.logger.preflight import check_log_directory


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.fixture
def shell_umask():
    old = os.umask(0o022)
    yield
    os.umask(old)


def test_preflight_makes_the_log_directory_and_its_parents_0750(tmp_path, shell_umask):
    check_log_directory(tmp_path / "var" / "haulprofile" / "logs")
    assert [mode(tmp_path / p) for p in ("var", "var/haulprofile", "var/haulprofile/logs")] == [0o750] * 3


def test_fleet_outputs_are_0640(tmp_path, shell_umask):
    from haulprofile.analysis.fleet import FleetSpec, run_fleet
    from test_fleet import VEHICLE, drive_signals

    tables = tmp_path / "tables"
    tables.mkdir()
    for seed in (0, 1):
        drive_signals(seed, 900.0).to_parquet(tables / f"drive-{seed}.parquet")
    out = tmp_path / "out"
    spec = FleetSpec.of([tables], [VEHICLE], n_candidates=200, seed=5, duration_s=300.0)
    run_fleet(spec, out, workers=1, say=lambda _m: None)
    files = [p for p in out.rglob("*") if p.is_file()]
    assert len(files) > 5 and {p.relative_to(out).as_posix(): mode(p) for p in files if mode(p) != 0o640} == {}
    assert {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_dir() and mode(p) != 0o750} == set()


def test_the_stage_cache_of_a_failed_run_is_0640(tmp_path, shell_umask, monkeypatch):
    from haulprofile.analysis.kinematics import KinematicsOptions
    from haulprofile.testing.drives import synthetic_drive

    table = tmp_path / "drive.csv"
    synthetic_drive(600, seed=4).round(3).drop(columns=["distance_m"]).to_csv(table, index=False)

    def fails(ctx):
        raise RuntimeError("a stage that fails")

    monkeypatch.setattr(pipeline, "STAGES", [s for s in pipeline.STAGES if s.name == "kinematics"]
                        + [pipeline.Stage("fails", KinematicsOptions, fails)])
    with pytest.raises(RuntimeError):
        run(RunContext(inputs=[table], out_dir=tmp_path / "out", say=lambda _m: None), cache=True)
    cached = [p for p in (tmp_path / "out").rglob("*") if p.is_file()]
    assert cached and {p.name: mode(p) for p in cached if mode(p) != 0o640} == {}


@pytest.mark.parametrize("corners, message", [
    ([[48.0, 11.0], [48.001, 11.001], [48.001, 11.0], [48.0, 11.001]], "crosses itself"),
    ([[48.0, 11.0], [48.001, 11.001], [48.002, 11.002]], "no area"),
    ([[48.0, 11.0], [48.0, 11.0], [48.0, 11.0]], "no area"),
])
def test_zone_polygons_that_enclose_nothing_or_cross_themselves_are_refused(corners, message):
    with pytest.raises(ValueError, match=message):
        zones_from_tables([{"name": "depot", "polygon": corners}])
