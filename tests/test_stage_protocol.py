"""A stage is one unit: a stage declared here, in the test, and added to `pipeline.STAGES` gets its
options, its result in memory, its summary key, its file and its report chapter, with nothing
else in the package changed."""

import json
from dataclasses import dataclass

import pytest

from haulprofile.analysis import pipeline
from haulprofile.analysis.pipeline import Options, RunContext, run
from haulprofile.analysis.report.html import Section
from haulprofile.analysis.stage import Stage
from haulprofile.testing.drives import synthetic_drive


@dataclass(frozen=True)
class FastOptions:
    threshold_mps: float = 20.0
    """Speed above which a sample counts as fast [m/s]."""


class FastResult(tuple):
    """(number of fast samples, threshold [m/s]): any type with summary() will do."""

    n_fast = property(lambda self: self[0])

    def summary(self) -> dict:
        return dict(zip(("n_fast", "threshold_mps"), self))

    def problem(self):
        return None if self.n_fast else "never fast"


def fast_stage(ctx) -> FastResult:
    threshold = ctx.options.fast.threshold_mps
    return FastResult((int((ctx.signals["speed_mps"] > threshold).sum()), threshold))


def write_fast(result: FastResult, folder, figures: bool) -> list[str]:
    (folder / "fast.txt").write_text(f"{result.n_fast}\n")
    return ["fast.txt"]


def fast_chapter(summary: dict, folder) -> Section:
    section = Section("Fast samples")
    section.paragraphs.append(f"{summary['n_fast']} samples above {summary['threshold_mps']:g} m/s "
                              f"(file beside: {(folder / 'fast.txt').is_file()})")
    return section


FAST = Stage("fast", FastOptions, fast_stage, write=write_fast, files=("fast.txt",), folder="fast",
             chapter=fast_chapter, title="Fast samples")


@pytest.fixture
def with_fast(monkeypatch):
    stages = [s for s in pipeline.STAGES if s.name == "kinematics"] + [FAST]
    monkeypatch.setattr(pipeline, "STAGES", stages)


@pytest.fixture
def table(tmp_path):
    path = tmp_path / "drive.csv"
    synthetic_drive(600, seed=3).to_csv(path, index=False)
    return path


def test_a_stage_declared_outside_the_package_runs_writes_and_reports(with_fast, table, tmp_path):
    out = tmp_path / "out"
    ctx = run(RunContext(inputs=[table], out_dir=out, options={"fast": {"threshold_mps": 10.0}}, say=lambda _m: None))
    n_fast = int((ctx.signals["speed_mps"] > 10.0).sum())
    assert 0 < n_fast < len(ctx.signals)
    assert ctx.results.fast.n_fast == n_fast
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fast"] == {"n_fast": n_fast, "threshold_mps": 10.0}
    assert summary["stages"] == ["kinematics", "fast", "report"]
    assert (out / "fast" / "fast.txt").read_text() == f"{n_fast}\n"
    report = (out / "report.html").read_text()
    assert "Fast samples" in report and f"{n_fast} samples above 10 m/s (file beside: True)" in report


def test_its_result_judges_the_run_and_its_options_are_checked(with_fast, table, tmp_path):
    ctx = run(RunContext(inputs=[table], out_dir=tmp_path / "o", options={"fast": {"threshold_mps": 1e3}},
                         say=lambda _m: None))
    assert pipeline.verdict(ctx) == "never fast"
    with pytest.raises(Exception, match="unknown key 'limit'"):
        Options.of({"fast": {"limit": 3}})


def test_a_skipped_stage_says_why_in_its_chapter(with_fast, table, tmp_path, monkeypatch):
    def skipped(ctx):
        ctx.skip("fast", "no speed above anything")

    from dataclasses import replace
    monkeypatch.setattr(pipeline, "STAGES", [pipeline.STAGES[0], replace(FAST, run=skipped)])
    out = tmp_path / "o"
    run(RunContext(inputs=[table], out_dir=out, say=lambda _m: None))
    assert json.loads((out / "summary.json").read_text())["skipped"] == {"fast": "no speed above anything"}
    assert not (out / "fast").exists()
    assert "Not run: no speed above anything." in (out / "report.html").read_text()
