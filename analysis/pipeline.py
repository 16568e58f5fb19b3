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


# (stage name, module, function). Order is the order of the analysis.
STAGES: list[tuple[str, str, str]] = [
    ("ingest", "analysis.ingest", "stage"),
    ("kinematics", "analysis.kinematics", "stage"),
    ("gradient", "analysis.gradient", "stage"),
    ("mass", "analysis.mass", "stage"),
    ("cycle", "analysis.markov", "stage"),
    ("loads", "analysis.loads", "stage"),
    ("simulate", "analysis.simulate", "stage"),
    ("report", "analysis.report", "stage"),
]


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


def run(ctx: RunContext) -> RunContext:
    """Run every available stage and write ``signals.parquet`` and ``summary.json``."""
    ctx.out_dir.mkdir(parents=True, exist_ok=True)
    load_inputs(ctx)
    ctx.summary.setdefault("stages", [])
    for name, stage in available_stages():
        if name == "ingest" and ctx.signals is not None:
            continue
        ctx.say(f"[{name}]")
        stage(ctx)
        ctx.summary["stages"].append(name)
    if ctx.signals is None:
        raise UserError("no signals: the inputs are logs but no ingest stage is installed")
    signals_table.write_signals(ctx.signals, ctx.out_dir / "signals.parquet")
    (ctx.out_dir / "summary.json").write_text(json.dumps(ctx.summary, indent=2, default=_jsonable))
    return ctx


def _jsonable(value):
    if hasattr(value, "item"):
        return value.item()
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
