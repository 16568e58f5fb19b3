"""The pipeline behind every ``analyze`` command: inputs → signals table → stages → one output step.

Stages are plain functions, listed in order in `STAGES`. A stage takes the `RunContext`, adds
columns to ``ctx.signals``, puts its typed result into ``ctx.results`` (the gradient grid, the mass
result, the selected cycle, the load collectives, the simulated cycle) and its numbers into
``ctx.summary``; the stages after it read those in memory. A stage writes no file: once the stages
ran, `analysis.outputs.write_outputs` writes every file, so an interrupted run leaves an earlier
run's outputs as they were. A stage whose inputs are missing is skipped with a line saying why
(`RunContext.skip`), never faked.
"""

from __future__ import annotations

import time
import typing
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, NamedTuple

import pandas as pd

from . import signals as signals_table
from .errors import UserError
from .gradient.estimate import GradientResult
from .gradient.stage import GradientOptions, gradient_stage
from .ingest.stage import IngestOptions, ingest_stage
from .kinematics import KinematicsOptions, kinematics_stage
from .loads.stage import LoadsOptions, LoadsResult, loads_stage
from .markov.stage import CycleOptions, CycleResult, cycle_stage
from .mass import MassResult
from .mass.stage import MassOptions, mass_stage
from .options import options_of
from .outputs import OutputOptions, check as check_outputs, write_outputs
from .simulate.model import SimulationResult
from .simulate.stage import SimulateOptions, simulate_stage
from .stage_cache import StageCache
from .vehicle import Vehicle


class Stage(NamedTuple):
    name: str
    run: Callable[["RunContext"], None]
    reads_vehicle: bool = False
    """A change of the vehicle file reruns it (and everything after it)."""
    reads_dem: bool = False
    """A change of the DEM tiles reruns it."""
    needs_signals: bool = True


STAGES: list[Stage] = [
    Stage("ingest", ingest_stage, needs_signals=False),
    Stage("kinematics", kinematics_stage),
    Stage("gradient", gradient_stage, reads_dem=True, reads_vehicle=True),
    Stage("mass", mass_stage, reads_vehicle=True),
    Stage("cycle", cycle_stage, reads_vehicle=True),
    Stage("loads", loads_stage, reads_vehicle=True),
    Stage("simulate", simulate_stage, reads_vehicle=True, needs_signals=False),
]
"""The analysis in order. ``report`` is not a stage: the output step writes it after the files it shows."""

REPORT = "report"


@dataclass
class Options:
    """Every stage's options, by stage name, and the output step's (``output``)."""

    ingest: IngestOptions = field(default_factory=IngestOptions)
    kinematics: KinematicsOptions = field(default_factory=KinematicsOptions)
    gradient: GradientOptions = field(default_factory=GradientOptions)
    mass: MassOptions = field(default_factory=MassOptions)
    cycle: CycleOptions = field(default_factory=CycleOptions)
    loads: LoadsOptions = field(default_factory=LoadsOptions)
    simulate: SimulateOptions = field(default_factory=SimulateOptions)
    output: OutputOptions = field(default_factory=OutputOptions)

    @classmethod
    def of(cls, tables: "Options | dict | None") -> "Options":
        """Options from per-stage keyword tables or option objects (``{"cycle": {"seed": 1}}``);
        ``mass_filter`` is the mass stage's data filter table."""
        if isinstance(tables, cls):
            return tables
        tables = dict(tables or {})
        if "mass_filter" in tables:
            mass = options_of(MassOptions, tables.get("mass"), "mass")
            tables["mass"] = replace(mass, filter=options_of(type(mass.filter), tables.pop("mass_filter"),
                                                             "mass_filter"))
        hints = typing.get_type_hints(cls)
        for name in tables:
            if name not in hints:
                raise UserError(f"no stage named {name} to take options (stages: {', '.join(hints)})")
        return cls(**{name: options_of(hints[name], table, name) for name, table in tables.items()})


@dataclass
class Results:
    """What the stages hand over in memory (None: the stage did not run or was skipped)."""

    gradient: GradientResult | None = None
    mass: MassResult | None = None
    cycle: CycleResult | None = None
    loads: LoadsResult | None = None
    simulation: SimulationResult | None = None


@dataclass
class RunContext:
    """One run: its inputs, options and, as the stages go, the signals table, results and summary."""

    inputs: list[Path]
    out_dir: Path
    vehicle: Vehicle | None = None
    dem_dir: Path | None = None
    options: Options | dict = field(default_factory=Options)
    signals: pd.DataFrame | None = None
    summary: dict = field(default_factory=dict)
    say: Callable[[str], None] = print
    figures: bool = True
    """Draw each stage's figure (a fleet's per-log runs may leave them out: some 30 % of their time)."""
    results: Results = field(default_factory=Results)
    skipped: dict[str, str] = field(default_factory=dict)
    """Stage name → why it was skipped."""
    subdirs: dict[str, str] = field(default_factory=lambda: {"loads": "loads", "simulate": "simulation"})
    """Folder of the output directory for the loads and simulate files ("" for the folder itself)."""
    json_files: dict[str, Callable[["RunContext"], object]] = field(default_factory=dict)
    """Further JSON files of a command: file name → what to write (None: no file)."""
    from_cache: set[str] = field(default_factory=set)
    """Stages whose results this run took from the stage cache."""
    cache_dir: Path | None = None
    """The stage cache's folder, where the output step also keeps each stage's files."""
    signals_name: str | None = None
    """Write the signals table under this name (``.csv`` or ``.parquet``) after any run, not only
    as ``signals.parquet`` after the full run (``analyze signals -o``)."""

    def __post_init__(self):
        self.inputs = [Path(p) for p in self.inputs]
        self.out_dir = Path(self.out_dir)
        self.dem_dir = Path(self.dem_dir) if self.dem_dir is not None else None
        self.options = Options.of(self.options)

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


def run(ctx: RunContext, until: str | None = None, start: str | None = None, cache: bool = False,
        progress: bool = False) -> RunContext:
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

    Returns
    -------
    RunContext
        ``ctx``, with ``signals``, ``results``, ``summary`` and ``skipped`` filled in.
    """
    check_outputs(ctx)
    load_inputs(ctx)
    ctx.summary.setdefault("stages", [])
    last = _index(until) if until is not None else len(STAGES)
    first = _index(start) if start is not None else 0
    full = last >= len(STAGES)
    stages = STAGES[first:last + 1]
    if ctx.signals is not None:
        stages = [stage for stage in stages if stage.name != "ingest"]
    store = StageCache(ctx, stages) if cache and ctx.inputs and not ctx.options.output.private else None
    done = store.restore() if store else 0
    ctx.cache_dir = store.directory if store else None
    ctx.from_cache = {stage.name for stage in stages[:done]}
    for stage in stages[:done]:
        ctx.say(f"[{stage.name}] unchanged, from cache")
    bar = _progress(stages[done:], progress)
    for stage in bar:
        if hasattr(bar, "set_description"):
            bar.set_description(stage.name)
        else:
            ctx.say(f"[{stage.name}]")
        if stage.needs_signals and ctx.signals is None:
            raise UserError("no signals: give logs or a signals table")
        started = time.perf_counter()
        stage.run(ctx)
        ctx.say(f"[{stage.name}] {time.perf_counter() - started:.1f} s")
        ctx.summary["stages"].append(stage.name)
        if store:
            store.save(stage.name)
    write_outputs(ctx, full)
    return ctx


def _progress(stages, enabled: bool):
    if not enabled:
        return stages
    from tqdm import tqdm

    return tqdm(stages, unit="stage", leave=False)
