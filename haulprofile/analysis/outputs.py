"""The one output step: every file of a run, written after its stages, so that an interrupted run
never poses as a finished one.

The files are written into a hidden folder inside the output directory, then moved into place
(a rename on the same file system); the earlier run's ``summary.json`` is removed before the first
file is moved, and the new one is moved last. Interrupted while writing, the directory still holds
the earlier run as it was; interrupted while moving, it holds no ``summary.json``. A full run also
removes the files of stages that did not run this time, so nothing of an earlier run stays beside
the new summary.

Every file and folder it writes is 0640 / 0750 whatever the umask (`haulprofile.private_files`):
the signals table, the report and the summary hold a driver's positions and times. With
`OutputOptions.private` the positions and wall-clock times stay out of the files altogether.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from haulprofile.private_files import make_dirs, restrict_tree

from . import checks, jsonable
from .errors import UserError

SUMMARY = "summary.json"
RUN_FILES = ("gradient.csv", "gradient.png", "mass.png", "cycle.csv", "cycle.parquet", "cycle.vdri", "cycle.png",
             "cycle-scores.png", "cycles", "loads", "simulation", "report.html", "signals.parquet", "design")
"""What a full run may write besides the summary; what it did not write this time is removed."""


@dataclass
class OutputOptions:
    """What the output step writes (``analyze run --private``)."""

    private: bool = False
    """Keep positions and wall-clock time (`signals.POSITION_COLUMNS`) out of the signals table and
    the report; heights, gradients, distances and times since the start stay. The stages used them
    in memory (the DEM); the pipeline keeps no stage cache, which would hold them."""


def _kept(ctx, stage: str, staging: Path, write):
    """What ``write()`` returns (the names it wrote into ``staging``). A stage the run took from
    the stage cache gets the files kept there when it last ran, instead of drawing them again; a
    stage that ran keeps its files there for the next run."""
    if ctx.cache_dir is None:
        return write()
    kept = ctx.cache_dir / stage / "files"
    index = kept / "index.json"
    if stage in ctx.from_cache and index.is_file():
        record = json.loads(index.read_text())
        for name in record["paths"]:
            copy = shutil.copytree if (kept / name).is_dir() else shutil.copy2
            copy(kept / name, staging / name)
        return record["value"]
    value = write()
    paths = [name for name in (value.values() if isinstance(value, dict) else value)]
    if kept.exists():
        shutil.rmtree(kept)
    kept.mkdir(parents=True)
    for name in paths:
        copy = shutil.copytree if (staging / name).is_dir() else shutil.copy2
        copy(staging / name, kept / name)
    index.write_text(json.dumps({"value": value, "paths": paths}))
    return value


def _stage_files(ctx, staging: Path, full: bool) -> None:
    from .gradient.stage import write_gradient
    from .loads.stage import write_loads
    from .markov.stage import write_cycle_files
    from .mass.stage import write_mass
    from .simulate.output import write_outputs as write_simulation

    results, summary = ctx.results, ctx.summary
    if results.gradient is not None:
        summary["gradient"]["files"] = _kept(ctx, "gradient", staging, lambda: write_gradient(
            results.gradient, staging, ctx.figures))
    if results.mass is not None:
        summary["mass"]["files"] = _kept(ctx, "mass", staging, lambda: write_mass(
            results.mass, ctx.signals, staging, ctx.figures, ctx.options.mass.true_mass_kg))
    if results.cycle is not None:
        summary["cycle"]["files"] = _kept(ctx, "cycle", staging, lambda: write_cycle_files(
            results.cycle, staging, ctx.figures))
    for stage, result, write in (("loads", results.loads, write_loads),
                                 ("simulate", results.simulation, write_simulation)):
        if result is not None:
            folder = ctx.subdirs[stage]

            def write_folder():
                written = write(result, staging / folder)
                return [folder] if folder else [Path(p).name for p in written]

            _kept(ctx, stage, staging, write_folder)
    if getattr(results, "design", None) is not None:
        from .design import write_design

        _kept(ctx, "design", staging, lambda: write_design(results.design, staging) and ["design"])
        summary["design"]["files"] = sorted(f"design/{p.name}" for p in (staging / "design").iterdir())
    for name, content in ctx.json_files.items():
        value = content(ctx)
        if value is not None:
            (staging / name).write_text(jsonable.dumps(value, indent=2))
    from .signals import without_positions, write_signals

    signals = ctx.signals
    if signals is not None and ctx.options.output.private:
        signals = without_positions(signals)
    if ctx.signals_name is not None and signals is not None:
        write_signals(signals, staging / ctx.signals_name)
    if full:
        from .report import write_report

        summary["stages"].append("report")
        summary["report"] = write_report(signals, summary, staging, ctx.vehicle)
        ctx.say(f"report: {ctx.out_dir / summary['report']}")
        write_signals(signals, staging / "signals.parquet")
        (staging / SUMMARY).write_text(jsonable.dumps(summary, indent=2))


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


def _files_read(ctx) -> list[Path]:
    """The run's inputs and the files its stage options name (a DBC, a cycle to simulate or compare)."""
    named = [getattr(table, f.name) for table in (getattr(ctx.options, t.name) for t in dataclasses.fields(ctx.options))
             for f in dataclasses.fields(table)]
    return list(ctx.inputs) + [value for value in named if isinstance(value, Path)]


def check(ctx) -> None:
    """Before any stage runs: the output directory can be written and nothing this run may write
    there is one of its inputs or an existing log (`checks.output_dir`)."""
    names = {*RUN_FILES, SUMMARY, *ctx.json_files, *(n for n in ctx.subdirs.values() if n)}
    if ctx.signals_name is not None:
        names.add(ctx.signals_name)
    checks.output_dir(ctx.out_dir, _files_read(ctx), names=sorted(names))


def write_outputs(ctx, full: bool) -> list[Path]:
    """Write the files of the stages that ran (and, for a ``full`` run, the report, signals table and
    summary) into ``ctx.out_dir``; returns the paths written, the summary last."""
    out = ctx.out_dir
    try:
        make_dirs(out)
        staging = Path(tempfile.mkdtemp(prefix=".partial-", dir=out))
    except OSError as exc:
        raise UserError(f"cannot write into {out}: {exc.strerror}") from None
    try:
        _stage_files(ctx, staging, full)
        restrict_tree(staging)
        if ctx.cache_dir is not None and ctx.cache_dir.exists():
            restrict_tree(ctx.cache_dir)
        names = sorted(p.name for p in staging.iterdir())
        if not names:
            return []
        if full or set(names) & set(RUN_FILES):
            (out / SUMMARY).unlink(missing_ok=True)  # the folder no longer holds one finished run
        if full:
            for name in RUN_FILES:
                if name not in names:
                    _remove(out / name)
        moved = []
        for name in [n for n in names if not (full and n == SUMMARY)] + ([SUMMARY] if full else []):
            if (staging / name).is_dir():
                _remove(out / name)
            os.replace(staging / name, out / name)
            moved.append(out / name)
        return moved
    finally:
        shutil.rmtree(staging, ignore_errors=True)
