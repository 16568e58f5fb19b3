"""The one output step: every file of a run, written after its stages, so that an interrupted run
never poses as a finished one.

The files are written into a hidden folder inside the output directory, then moved into place
(a rename on the same file system); the earlier run's ``summary.json`` is removed before the first
file is moved, and the new one is moved last. Interrupted while writing, the directory still holds
the earlier run as it was; interrupted while moving, it holds no ``summary.json``. A full run also
removes the files of stages that did not run this time, so nothing of an earlier run stays beside
the new summary.

Every file and folder it writes is 0640 / 0750 whatever the umask (`haulprofile.contract.private_files`):
the signals table, the report and the summary hold a driver's positions and times. With
`OutputOptions.private` the positions and wall-clock times stay out of the files altogether.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from haulprofile.contract.input_files import refuse_special
from haulprofile.contract.private_files import make_dirs, restrict_tree

from . import checks, jsonable
from .manifest import Manifest, refuse_link, staged_files
from .errors import UserError

SUMMARY = "summary.json"
REPORT_FILES = ("report.html", "signals.parquet")
"""What a full run writes besides its stages' files and the summary."""
OUTPUT = "output"
"""The output step's name among the options (``options.output``)."""


@dataclass(frozen=True)
class OutputOptions:
    """What the output step writes."""

    private: bool = False
    """Keep positions and wall-clock time (`signals.POSITION_COLUMNS`) out of the signals table and
    the report; heights, gradients, distances and times since the start stay. The stages used them
    in memory (the DEM); the pipeline keeps no stage cache, which would hold them."""
    figures: bool = True
    """Draw each stage's figures (a fleet's per-log runs may leave them out: some 30 % of their time)."""
    flat: tuple[str, ...] = ()
    """Stages whose files go into the output directory itself instead of their folder
    (``analyze loads -o DIR``)."""
    summary_files: tuple[str, ...] = ()
    """Stages whose summary is also written as ``<stage>.json`` (``analyze cycle``, ``analyze mass``)."""
    signals_file: str | None = None
    """Write the signals table under this name (``.csv`` or ``.parquet``) after any run, not only
    as ``signals.parquet`` after the full run (``analyze signals -o``)."""


def _folder(stage, options: OutputOptions) -> str:
    return "" if stage.name in options.flat else stage.folder


def run_files(stages, options: OutputOptions) -> list[str]:
    """Every name a run of ``stages`` may write into the output directory besides the summary."""
    names = set(REPORT_FILES) | {f"{stage.key or stage.name}.json" for stage in stages
                                 if stage.name in options.summary_files}
    for stage in stages:
        folder = _folder(stage, options)
        names |= {folder} if folder else set(stage.files)
    if options.signals_file is not None:
        names.add(options.signals_file)
    return sorted(names)


def _kept(store, stage: str, staging: Path, write):
    """What ``write()`` returns (the names it wrote into ``staging``). A stage the run took from
    the stage cache gets the files kept there when it last ran, instead of drawing them again; a
    stage that ran keeps its files there for the next run."""
    if store is None:
        return write()
    kept = store.directory / stage / "files"
    index = kept / "index.json"
    if stage in store.restored and index.is_file():
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


def _stage_files(ctx, stages, staging: Path, full: bool, store) -> None:
    options: OutputOptions = ctx.options.output
    summary = ctx.summary
    for stage in stages:
        result = ctx.results.get(stage.name)
        if result is None or stage.write is None:
            continue
        folder = _folder(stage, options)

        def write(stage=stage, result=result, folder=folder):
            target = staging / folder
            target.mkdir(parents=True, exist_ok=True)
            written = stage.write(result, target, options.figures)
            if not folder:
                return written
            names = list(written.values()) if isinstance(written, dict) else list(written)
            return [folder] if names else []

        written = _kept(store, stage.name, staging, write)
        if stage.key and isinstance(summary.get(stage.key), dict) and not stage.folder:
            summary[stage.key]["files"] = written
    for name in options.summary_files:
        stage = next(s for s in stages if s.name == name)
        if stage.key in summary:
            (staging / f"{stage.key}.json").write_text(jsonable.dumps(summary[stage.key], indent=2))
    from .signals import without_positions, write_signals

    signals = ctx.signals
    if signals is not None and options.private:
        signals = without_positions(signals)
    if options.signals_file is not None and signals is not None:
        write_signals(signals, staging / options.signals_file)
    if full:
        from .report import write_report

        summary["stages"].append("report")
        summary["report"] = write_report(signals, summary, staging, ctx.vehicle, stages, ctx.dem_dir, options.private)
        ctx.say(f"report: {ctx.out_dir / summary['report']}")
        write_signals(signals, staging / "signals.parquet")
        (staging / SUMMARY).write_text(jsonable.dumps(summary, indent=2))


def _remove(manifest: Manifest, path: Path) -> None:
    """Remove ``path`` if this tool wrote it (a file the user put there or replaced stays)."""
    manifest.remove(path)


def _files_read(ctx) -> list[Path]:
    """The run's inputs and the files its stage options name (a DBC, a cycle to simulate or compare)."""
    named = [getattr(table, f.name) for table in ctx.options.tables().values() for f in dataclasses.fields(table)]
    return list(ctx.inputs) + [value for value in named if isinstance(value, Path)]


def check(ctx, stages) -> None:
    """Before any stage runs: the output directory can be written and nothing this run may write
    there is one of its inputs, an existing log, a symbolic link or a file this tool did not write
    (`checks.output_dir`, `manifest.Manifest`); no input, file named by an option or DEM is a
    device, FIFO or socket, whose reading might never end (`input_files.refuse_special`)."""
    for path in _files_read(ctx):
        refuse_special(path, "input", UserError)
    if ctx.dem_dir is not None:
        refuse_special(ctx.dem_dir, "DEM directory", UserError)
    names = {*run_files(stages, ctx.options.output), SUMMARY}
    checks.output_dir(ctx.out_dir, _files_read(ctx), names=sorted(names))
    manifest = Manifest(ctx.out_dir)
    for name in sorted(names):
        if not (ctx.out_dir / name).is_dir() or (ctx.out_dir / name).is_symlink():
            manifest.check_target(ctx.out_dir / name)


def write_outputs(ctx, stages, full: bool, store=None) -> list[Path]:
    """Write the files of ``stages`` that ran (and, for a ``full`` run, the report, signals table
    and summary) into ``ctx.out_dir``; ``store`` is the run's stage cache, if any. Returns the
    paths written (top-level files and folders), the summary last. Files are moved in one by one:
    a folder such as ``loads/`` keeps what else it holds, and only files this tool wrote are
    replaced or removed (`manifest.Manifest`)."""
    out = ctx.out_dir
    refuse_link(out)
    try:
        make_dirs(out)
        staging = Path(tempfile.mkdtemp(prefix=".partial-", dir=out))
    except OSError as exc:
        raise UserError(f"cannot write into {out}: {exc.strerror}") from None
    try:
        _stage_files(ctx, stages, staging, full, store)
        restrict_tree(staging)
        if store is not None and store.directory.exists():
            restrict_tree(store.directory)
        run_names = set(run_files(stages, ctx.options.output))
        staged = staged_files(staging)
        if not staged:
            return []
        manifest = Manifest(out)
        tops = {rel.parts[0] for rel in staged}
        drop_summary = full or bool(tops & run_names)
        for rel in staged + ([Path(SUMMARY)] if drop_summary else []):
            manifest.check_target(out / rel)
        stale = [path for top in (run_names if full else set()) | {t for t in tops if (staging / t).is_dir()}
                 for path in manifest.under(top) if path.relative_to(out) not in staged]
        if drop_summary:
            _remove(manifest, out / SUMMARY)  # the folder no longer holds one finished run
        for path in stale:
            _remove(manifest, path)
        order = [rel for rel in staged if not (full and rel == Path(SUMMARY))] + ([Path(SUMMARY)] if full else [])
        manifest.place(staging, order)
        moved: list[Path] = []
        for rel in order:
            if out / rel.parts[0] not in moved:
                moved.append(out / rel.parts[0])
        return moved
    finally:
        shutil.rmtree(staging, ignore_errors=True)
