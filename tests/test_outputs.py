"""The output step and the stage cache: an interrupted run never poses as a finished one, and the
cache knows a log by its content, not by its size and time stamp."""

import json
from dataclasses import replace
import os

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import outputs, pipeline
from haulprofile.analysis.errors import UserError
from haulprofile.analysis.pipeline import RunContext, run
from haulprofile.testing.drives import synthetic_drive

CYCLE = {"n_candidates": 200, "duration_s": 300.0}


@pytest.fixture
def quick_stages(monkeypatch):
    """Kinematics, cycle and loads (skipped without a vehicle): output files in seconds."""
    monkeypatch.setattr(pipeline, "STAGES", [s for s in pipeline.STAGES if s.name in ("kinematics", "cycle", "loads")])


@pytest.fixture
def table(tmp_path):
    path = tmp_path / "drive.csv"
    synthetic_drive(1200, seed=4).round(3).drop(columns=["distance_m"]).to_csv(path, index=False)
    return path


def snapshot(directory):
    return {p.relative_to(directory).as_posix(): p.read_bytes() for p in sorted(directory.rglob("*"))
            if p.is_file() and ".cache" not in p.parts}


def earlier_run(table, out):
    run(RunContext(inputs=[table], out_dir=out, options={"cycle": {**CYCLE, "seed": 1}}, say=lambda _m: None))
    return snapshot(out)


def test_interrupted_in_a_stage_after_the_cycle_leaves_the_earlier_run_as_it_was(quick_stages, table, tmp_path, monkeypatch):
    out = tmp_path / "out"
    before = earlier_run(table, out)
    assert {"summary.json", "report.html", "signals.parquet", "cycle.csv", "cycle.vdri"} <= set(before)

    def interrupted(ctx):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "STAGES", [replace(s, run=interrupted) if s.name == "loads" else s
                                             for s in pipeline.STAGES])
    with pytest.raises(KeyboardInterrupt):
        run(RunContext(inputs=[table], out_dir=out, options={"cycle": {**CYCLE, "seed": 2}}, say=lambda _m: None))
    assert snapshot(out) == before


def test_interrupted_while_writing_leaves_the_earlier_run_and_no_partial_folder(quick_stages, table, tmp_path,
                                                                                monkeypatch):
    out = tmp_path / "out"
    before = earlier_run(table, out)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("haulprofile.analysis.report.write_report", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run(RunContext(inputs=[table], out_dir=out, options={"cycle": {**CYCLE, "seed": 2}}, say=lambda _m: None))
    assert snapshot(out) == before
    assert not [p for p in out.iterdir() if p.name.startswith(".partial-")]


def test_interrupted_while_moving_into_place_leaves_no_summary(quick_stages, table, tmp_path, monkeypatch):
    out = tmp_path / "out"
    earlier_run(table, out)
    moved = []

    def replace_then_interrupt(source, target):
        if moved:
            raise KeyboardInterrupt
        moved.append(target)
        os.rename(source, target)

    monkeypatch.setattr(outputs.os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        run(RunContext(inputs=[table], out_dir=out, options={"cycle": {**CYCLE, "seed": 2}}, say=lambda _m: None))
    assert len(moved) == 1 and not (out / "summary.json").exists()


def test_a_full_run_removes_what_an_earlier_run_wrote_and_this_one_did_not(quick_stages, table, tmp_path,
                                                                          monkeypatch):
    out = tmp_path / "out"
    earlier_run(table, out)

    def no_cycle(ctx):
        ctx.skip("cycle", "no gradient")

    monkeypatch.setattr(pipeline, "STAGES", [replace(s, run=no_cycle) if s.name == "cycle" else s
                                             for s in pipeline.STAGES])
    run(RunContext(inputs=[table], out_dir=out, say=lambda _m: None))
    assert not (out / "cycle.csv").exists() and not (out / "cycle.vdri").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert "cycle" not in summary and summary["skipped"]["cycle"] == "no gradient"


def test_the_signals_table_is_never_written_over_an_input(tmp_path, table):
    ctx = RunContext(inputs=[table], out_dir=table.parent, options={"output": {"signals_file": table.name}},
                     say=lambda _m: None)
    with pytest.raises(UserError, match="is an input"):
        run(ctx, until="ingest")
    assert pd.read_csv(table).shape[0] > 0


def test_the_cache_keys_on_content_not_size_and_time(quick_stages, table, tmp_path):
    out = tmp_path / "out"

    def cached_run():
        said = []
        ctx = run(RunContext(inputs=[table], out_dir=out, options={"cycle": CYCLE}, say=said.append), cache=True)
        return ctx, said

    cached_run()
    first = snapshot(out)
    _, said = cached_run()
    assert "[kinematics] unchanged, from cache" in said and "[cycle] unchanged, from cache" in said
    again = snapshot(out)
    assert {name: again[name] for name in ("cycle.csv", "cycle.vdri", "cycle.png")} == \
        {name: first[name] for name in ("cycle.csv", "cycle.vdri", "cycle.png")}
    frame = pd.read_csv(table)
    stat = table.stat()
    size = stat.st_size
    frame["speed_mps"] = frame["speed_mps"].to_numpy()[::-1]
    frame.to_csv(table, index=False)
    os.utime(table, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert table.stat().st_size == size and table.stat().st_mtime_ns == stat.st_mtime_ns
    ctx, said = cached_run()
    assert not any("from cache" in line for line in said)
    np.testing.assert_array_equal(ctx.signals["speed_mps"].to_numpy(), frame["speed_mps"].to_numpy())


def test_a_partial_run_into_a_finished_run_leaves_no_summary_beside_its_files(quick_stages, table, tmp_path):
    out = tmp_path / "out"
    earlier_run(table, out)
    run(RunContext(inputs=[table], out_dir=out, options={"cycle": {**CYCLE, "seed": 2}}, say=lambda _m: None),
        until="cycle")
    assert (out / "cycle.csv").is_file() and not (out / "summary.json").exists()
