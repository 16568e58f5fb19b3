"""The pipeline behind every ``analyze`` command: inputs → signals table → stages → one output step.

The stages are listed in order in `STAGES`, each declared by its own folder (`stage.Stage`). A
stage takes the `RunContext`, adds columns to ``ctx.signals`` and returns its typed result; the
pipeline keeps it in ``ctx.results`` under the stage's name (the stages after it read it there, in
memory) and its ``summary()`` in ``ctx.summary``. A stage writes no file: once the stages ran,
`analysis.outputs.write_outputs` writes every stage's files, so an interrupted run leaves an
earlier run's outputs as they were. A stage whose inputs are missing is skipped with a line saying
why (`RunContext.skip`), never faked.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import pandas as pd

from . import signals as signals_table
from .errors import UserError
from .gradient.stage import STAGE as GRADIENT
from .ingest.stage import STAGE as INGEST
from .kinematics import STAGE as KINEMATICS
from .loads.stage import STAGE as LOADS
from .markov.stage import STAGE as CYCLE
from .mass.stage import STAGE as MASS
from .options import options_of
from .outputs import OUTPUT, OutputOptions, check as check_outputs, write_outputs
from .simulate.stage import STAGE as SIMULATION
from .design.stage import STAGE as DESIGN
from .stage import Results, Stage
from .stage_cache import StageCache
from .vehicle import Vehicle

STAGES: list[Stage] = [INGEST, KINEMATICS, GRADIENT, MASS, CYCLE, LOADS, SIMULATION, DESIGN]
"""The analysis in order. ``report`` is not a stage: the output step writes it after the files it shows."""

REPORT = "report"


class Options:
    """Every stage's options by stage name (``options.cycle``), and the output step's (``output``).

    The names come from `STAGES` when the options are made, so a stage added there takes options
    with no further line; each is its stage's options dataclass, its defaults where not given."""

    def __init__(self, **tables):
        types = option_types()
        for name in tables:
            if name not in types:
                raise UserError(f"no stage named {name} to take options (stages: {', '.join(types)})")
        for name, cls in types.items():
            object.__setattr__(self, name, options_of(cls, tables.get(name), name))

    def __setattr__(self, name, value):
        raise AttributeError("options are fixed once made: use replace()")

    def __eq__(self, other) -> bool:
        return isinstance(other, Options) and vars(self) == vars(other)

    def __repr__(self) -> str:
        return f"Options({', '.join(f'{name}={value!r}' for name, value in vars(self).items())})"

    def tables(self) -> dict:
        """Stage name (and ``output``) → its options object."""
        return dict(vars(self))

    def replace(self, **changes) -> "Options":
        """These options with some stages' options replaced."""
        return Options(**{**vars(self), **changes})

    @classmethod
    def of(cls, tables: "Options | dict | None") -> "Options":
        """Options from per-stage keyword tables or option objects (``{"cycle": {"seed": 1}}``);
        ``mass_filter`` is the mass stage's data filter table."""
        if isinstance(tables, cls):
            return tables
        tables = dict(tables or {})
        if "mass_filter" in tables:
            mass = options_of(MASS.options, tables.get("mass"), "mass")
            tables["mass"] = replace(mass, filter=options_of(type(mass.filter), tables.pop("mass_filter"),
                                                             "mass_filter"))
        return cls(**tables)


def option_types() -> dict[str, type]:
    """Stage name → its options dataclass, and the output step's (``output``)."""
    return {**{stage.name: stage.options for stage in STAGES}, OUTPUT: OutputOptions}


@dataclass
class RunContext:
    """One run: its inputs and options and, as the stages go, the signals table, results and summary."""

    inputs: list[Path]
    out_dir: Path
    vehicle: Vehicle | None = None
    dem_dir: Path | None = None
    options: Options | dict = field(default_factory=Options)
    signals: pd.DataFrame | None = None
    summary: dict = field(default_factory=dict)
    say: Callable[[str], None] = print
    results: Results = field(default_factory=Results)
    skipped: dict[str, str] = field(default_factory=dict)
    """Stage name → why it was skipped."""

    def __post_init__(self):
        self.inputs = [Path(p) for p in self.inputs]
        self.out_dir = Path(self.out_dir)
        self.dem_dir = Path(self.dem_dir) if self.dem_dir is not None else None
        self.options = Options.of(self.options)
        if not isinstance(self.results, Results):
            self.results = Results(self.results)

    def skip(self, stage: str, reason: str) -> None:
        """Record and say that ``stage`` did not run, and why."""
        self.skipped[stage] = reason
        self.say(f"{stage}: skipped: {reason}")


def load_inputs(ctx: RunContext) -> None:
    """Signals tables are read directly; logs go through the ingest stage."""
    tables = [p for p in ctx.inputs if signals_table.is_signals_path(p)]
    if tables and len(tables) != len(ctx.inputs):
        raise UserError("give either logs or signals tables, not both")
    for path in ctx.inputs:
        if not path.exists():
            raise UserError(f"input {path} not found")
    if tables:
        ctx.signals = signals_table.combine(tables, ctx.say)


def stage_names() -> list[str]:
    return [stage.name for stage in STAGES] + [REPORT]


def _index(name: str) -> int:
    names = stage_names()
    if name not in names:
        raise UserError(f"no stage named {name} (stages: {', '.join(names)})")
    return names.index(name)


def run_stage(ctx: RunContext, stage: Stage) -> None:
    """Run one stage: its result into ``ctx.results``, its summary into ``ctx.summary``."""
    if stage.needs_signals and ctx.signals is None:
        raise UserError("no signals: give logs or a signals table")
    result = stage.run(ctx)
    ctx.results[stage.name] = result
    if result is None:
        return
    if stage.key:
        ctx.summary[stage.key] = result.summary()
    else:
        ctx.summary.update(result.summary())


def verdict(ctx: RunContext, stages=None) -> str | None:
    """One line when a result did not meet its criteria or a required stage was skipped, else None."""
    problems = []
    for stage in stages if stages is not None else STAGES:
        result = ctx.results.get(stage.name)
        if stage.name in ctx.skipped and stage.required:
            problems.append(f"no {stage.title or stage.name}: the {stage.name} stage was skipped "
                            f"({ctx.skipped[stage.name]})")
        elif result is not None and hasattr(result, "problem") and (problem := result.problem()):
            problems.append(problem)
    return "; ".join(problems) or None


def run(ctx: RunContext, until: str | None = None, start: str | None = None, cache: bool = False,
        progress: bool = False, leave_out: tuple[str, ...] = ()) -> RunContext:
    """Run the stages from ``start`` (the first) up to and including ``until`` (the report: all),
    then write their files in one output step; the full run also writes ``report.html``,
    ``signals.parquet`` and, last, ``summary.json``.

    Parameters
    ----------
    ctx : RunContext
        Inputs, vehicle, DEM and options; ``signals`` may be given instead of inputs.
    until : str, optional
        Name of the last stage to run (`STAGES`); None or ``"report"`` runs all and writes the report.
    start : str, optional
        Name of the first stage, for commands whose input is already what the stages before it
        make (``analyze loads`` starts at ``loads``).
    cache : bool
        Keep each stage's state under ``out_dir/.cache``, keyed by the content of the inputs, the
        options, vehicle and DEM it reads and the stages before it, so a rerun with one changed
        option reruns only the stages that depend on it. Not with ``options.output.private``: the
        cache would hold the positions.
    progress : bool
        A progress bar of the stages on stderr.
    leave_out : tuple of str
        Stages between ``start`` and ``until`` not to run (``analyze loads`` needs no cycle).

    Returns
    -------
    RunContext
        ``ctx``, with ``signals``, ``results``, ``summary`` and ``skipped`` filled in.
    """
    check_outputs(ctx, STAGES)
    load_inputs(ctx)
    ctx.summary.setdefault("stages", [])
    last = _index(until) if until is not None else len(STAGES)
    first = _index(start) if start is not None else 0
    full = last >= len(STAGES)
    stages = [stage for stage in STAGES[first:last + 1] if stage.name not in leave_out]
    if ctx.signals is not None:
        stages = [stage for stage in stages if stage.name != INGEST.name]
    store = StageCache(ctx, stages) if cache and ctx.inputs and not ctx.options.output.private else None
    done = store.restore() if store else 0
    for stage in stages[:done]:
        ctx.say(f"[{stage.name}] unchanged, from cache")
    bar = _progress(stages[done:], progress)
    for stage in bar:
        if hasattr(bar, "set_description"):
            bar.set_description(stage.name)
        else:
            ctx.say(f"[{stage.name}]")
        started = time.perf_counter()
        run_stage(ctx, stage)
        ctx.say(f"[{stage.name}] {time.perf_counter() - started:.1f} s")
        ctx.summary["stages"].append(stage.name)
        if store:
            store.save(stage.name)
    if ctx.skipped:
        ctx.summary["skipped"] = dict(ctx.skipped)
    write_outputs(ctx, STAGES, full, store)
    return ctx


def _progress(stages, enabled: bool):
    if not enabled:
        return stages
    from tqdm import tqdm

    return tqdm(stages, unit="stage", leave=False)
