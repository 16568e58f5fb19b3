"""The orchestrator behind ``analyze run``: inputs → signals table → every stage, in order.

Stages are listed once, in `STAGES`, as (name, module, function). A stage function takes the
`RunContext`, adds columns to ``ctx.signals`` and entries to ``ctx.summary``, and may write files
into ``ctx.out_dir``. A stage whose module is not installed is not listed; a stage whose input
columns are missing is skipped with a message saying which (never faked).
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import pandas as pd

from . import signals as signals_table
from .errors import UserError
from .vehicle import Vehicle


@dataclass
class RunContext:
    inputs: list[Path]
    out_dir: Path
    vehicle: Vehicle | None = None
    dem_dir: Path | None = None
    options: dict = field(default_factory=dict)
    signals: pd.DataFrame | None = None
    summary: dict = field(default_factory=dict)
    say: Callable[[str], None] = print
    figures: bool = True
    """Draw each stage's figure (a fleet's per-log runs may leave them out: some 30 % of their time)."""


# (stage name, module, function). Order is the order of the analysis.
STAGES: list[tuple[str, str, str]] = [
    ("ingest", "haulprofile.analysis.ingest", "stage"),
    ("kinematics", "haulprofile.analysis.kinematics", "stage"),
    ("gradient", "haulprofile.analysis.gradient", "stage"),
    ("mass", "haulprofile.analysis.mass", "stage"),
    ("cycle", "haulprofile.analysis.markov", "stage"),
    ("loads", "haulprofile.analysis.loads", "stage"),
    ("simulate", "haulprofile.analysis.simulate", "stage"),
    ("report", "haulprofile.analysis.report", "stage"),
]

# What each stage depends on besides the stages before it: its option tables in ``ctx.options``,
# and whether it reads the vehicle file or the DEM. A change there reruns it and everything after.
DEPENDS_ON: dict[str, dict] = {
    "ingest": {"options": ("ingest",)},
    "gradient": {"options": ("gradient",), "dem": True},
    "mass": {"options": ("mass", "mass_filter"), "vehicle": True},
    "cycle": {"options": ("cycle",)},
    "loads": {"options": ("loads",), "vehicle": True},
    "simulate": {"options": ("simulate",), "vehicle": True},
    "report": {"vehicle": True},
}


def available_stages() -> list[tuple[str, Callable[[RunContext], None]]]:
    stages = []
    for name, module_name, function in STAGES:
        if importlib.util.find_spec(module_name) is None:
            continue
        module = importlib.import_module(module_name)
        if hasattr(module, function):
            stages.append((name, getattr(module, function)))
    return stages


def load_inputs(ctx: RunContext) -> None:
    """Signals tables are read directly; logs go through the ingest stage."""
    tables = [p for p in ctx.inputs if signals_table.is_signals_path(p)]
    if tables and len(tables) != len(ctx.inputs):
        raise UserError("give either logs or signals tables, not both")
    for path in ctx.inputs:
        if not path.exists():
            raise UserError(f"input {path} not found")
    if tables:
        frames = [signals_table.read_signals(p) for p in tables]
        ctx.signals = signals_table.validate(pd.concat(frames, ignore_index=True), ", ".join(map(str, tables)))


def run(ctx: RunContext, until: str | None = None, cache: bool = False, progress: bool = False) -> RunContext:
    """Run the available stages in order (up to and including ``until``) and write
    ``signals.parquet`` and ``summary.json`` (the full run only).

    With ``cache``, each stage's result is kept under ``out_dir/.cache`` keyed by the inputs, the
    options, vehicle and DEM it depends on (`DEPENDS_ON`) and the stages before it, so a rerun with one
    changed option reruns only the stages that depend on it.
    """
    from .stage_cache import StageCache

    ctx.out_dir.mkdir(parents=True, exist_ok=True)
    load_inputs(ctx)
    ctx.summary.setdefault("stages", [])
    stages = available_stages()
    if until is not None:
        names = [name for name, _ in stages]
        if until not in names:
            raise UserError(f"no stage named {until} (stages: {', '.join(names)})")
        stages = stages[:names.index(until) + 1]
    if ctx.signals is not None:
        stages = [(name, stage) for name, stage in stages if name != "ingest"]
    store = StageCache(ctx) if cache else None
    start = store.restore([name for name, _ in stages]) if store else 0
    for name, _ in stages[:start]:
        ctx.say(f"[{name}] unchanged, from cache")
    bar = _progress(stages[start:], progress)
    for name, stage in bar:
        if hasattr(bar, "set_description"):
            bar.set_description(name)
        else:
            ctx.say(f"[{name}]")
        started = time.perf_counter()
        stage(ctx)
        elapsed = time.perf_counter() - started
        ctx.say(f"[{name}] {elapsed:.1f} s")
        if ctx.signals is None:
            raise UserError("no signals: the inputs are logs but no ingest stage is installed")
        ctx.summary["stages"].append(name)
        if store:
            store.save(name)
    if ctx.signals is None:
        raise UserError("no signals: the inputs are logs but no ingest stage is installed")
    if until is None:
        signals_table.write_signals(ctx.signals, ctx.out_dir / "signals.parquet")
        (ctx.out_dir / "summary.json").write_text(json.dumps(ctx.summary, indent=2, default=jsonable))
    return ctx


def _progress(stages, enabled: bool):
    if not enabled:
        return stages
    from tqdm import tqdm

    return tqdm(stages, unit="stage", leave=False)


def jsonable(value):
    """``json.dumps`` default for NumPy scalars/arrays and paths."""
    if hasattr(value, "item"):
        return value.item()
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
