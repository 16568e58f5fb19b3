"""The fleet's three functions, the same whichever executor runs them: `map_log` (one log →
its additive statistics), `reduce_group` (sum in path order) and `group_cycle` (the cycle of a
group's summed counts). Each takes and returns plain picklable objects."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from haulprofile.contract.private_files import make_dirs

from ..errors import UserError
from ..markov import ClassWidths, build_chain
from ..markov.stage import CycleOptions, select
from ..mass.joint import JointSettings
from ..pipeline import Options, RunContext, run as run_pipeline
from ..vehicle import Vehicle
from .cycle_target import load_target_of
from .road_load import segment_moments
from .statistics import FleetStatistics, LoadBins, log_statistics, sum_statistics


@dataclass
class LogTask:
    """One log of a group; its per-log outputs (the stages' figures, unless ``figures`` is off) go
    to ``out_dir``."""

    path: Path
    group: str
    vehicle: Vehicle
    out_dir: Path
    dem_dir: Path | None = None
    options: dict = field(default_factory=dict)
    widths: ClassWidths = field(default_factory=ClassWidths)
    bins: LoadBins = field(default_factory=LoadBins)
    debug: bool = False
    figures: bool = True
    log_dir: Path | None = None
    """The group's directory: the log is named by its path under it in the road-load fit."""


@dataclass
class LogResult:
    """A log's statistics, or why it failed (one line), with what its stages said."""

    path: Path
    group: str
    statistics: FleetStatistics | None
    error: str | None = None
    messages: list[str] = field(default_factory=list)
    dates: tuple[str, ...] = ()
    """UTC dates (YYYY-MM-DD) on which the truck moved, from the log's wall-clock time (the fleet
    report's km/day); empty without one."""


@dataclass
class GroupCycle:
    """A group's generated cycle and how it was chosen (`analysis.markov.Selection.as_dict`), or
    why there is none (one line)."""

    group: str
    cycle: object | None
    selection: dict
    error: str | None = None


def driving_dates(signals) -> tuple[str, ...]:
    """The UTC dates of the samples where the truck moved (speed above 0.5 m/s)."""
    if "wall_time_ns" not in signals.columns:
        return ()
    wall = pd.to_numeric(signals["wall_time_ns"], errors="coerce").to_numpy(float)
    moving = np.nan_to_num(signals["speed_mps"].to_numpy(float)) > 0.5
    days = np.unique(np.floor(wall[moving & np.isfinite(wall)] / 86_400e9)).astype("int64")
    return tuple(str(np.datetime64(int(day), "D")) for day in days)


def map_log(task: LogTask) -> LogResult:
    """Pipeline up to the mass stage on one log, then its additive statistics. A log that fails
    (a user error such as an unreadable file, or any other exception) is a result naming why,
    so the other logs go on; with ``task.debug`` the exception is raised. What the stages said
    goes to ``messages.txt`` in the log's output directory."""
    messages: list[str] = []
    options = Options.of(task.options)
    options = options.replace(output=replace(options.output, figures=task.figures))
    ctx = RunContext(inputs=[task.path], out_dir=task.out_dir, vehicle=task.vehicle, dem_dir=task.dem_dir,
                     options=options, say=messages.append)
    try:
        run_pipeline(ctx, until="mass")
        statistics = log_statistics(str(task.path), ctx.signals, ctx.summary, task.vehicle, task.widths, task.bins)
        if ctx.results.mass is not None:
            statistics.road_load_moments = segment_moments(_log_name(task), ctx.results.mass,
                                                           ctx.signals["time_s"].to_numpy(float), _joint_settings(ctx))
        result = LogResult(task.path, task.group, statistics, None, messages + statistics.notes,
                           driving_dates(ctx.signals))
    except UserError as exc:
        if task.debug:
            raise
        result = LogResult(task.path, task.group, None, str(exc), messages)
    except Exception as exc:  # noqa: BLE001 - one bad log must not stop a fleet; named in the result
        if task.debug:
            raise
        result = LogResult(task.path, task.group, None, f"internal error {type(exc).__name__}: {exc}", messages)
    make_dirs(task.out_dir)
    ending = [f"FAILED: {result.error}"] if result.error else []
    (task.out_dir / "messages.txt").write_text("\n".join([str(task.path), *result.messages, *ending]) + "\n")
    return result


def _log_name(task: LogTask) -> str:
    """The log's path under its group's directory (how ``--known-mass`` names it)."""
    try:
        return task.path.relative_to(task.log_dir).as_posix() if task.log_dir is not None else task.path.name
    except ValueError:
        return task.path.name


def _joint_settings(ctx):
    mass = getattr(ctx.options, "mass", None)
    return mass.joint if mass is not None else JointSettings()


def reduce_group(results: list[LogResult]) -> FleetStatistics | None:
    """Sum the statistics of a group's logs that succeeded, sorted by path; None if none did."""
    done = sorted((r for r in results if r.statistics is not None), key=lambda r: str(r.path))
    return sum_statistics([r.statistics for r in done]) if done else None


def group_cycle(group: str, statistics: FleetStatistics, duration_s: float, n_candidates: int | None,
                seed: int, vehicle: Vehicle | None = None) -> GroupCycle:
    """The cycle of the group's summed transition counts, selected as `analyze run` selects a
    drive's (`markov.stage.select`, refined; with ``vehicle``, towards the group's summed wheel
    loads, `cycle_target`); ``n_candidates`` the Monte Carlo pool (None: the run's default)."""
    if statistics.counts is None or len(statistics.counts) == 0:
        return GroupCycle(group, None, {}, "no transitions counted in any log (speed, gradient and mass are "
                                           "needed together; see the logs' notes)")
    options = CycleOptions(duration_s=duration_s, n_candidates=n_candidates, seed=seed, widths=statistics.counts.widths)
    try:
        chain = build_chain(statistics.counts)
        target = load_target_of(statistics, vehicle, chain) if vehicle is not None else None
        selection = select(options, statistics.counts, chain, target, vehicle if target is not None else None)[0]
    except UserError as exc:
        return GroupCycle(group, None, {}, str(exc))
    return GroupCycle(group, selection.cycle, selection.as_dict())


def group_cycle_job(job: tuple) -> GroupCycle:
    """`group_cycle` of one (group, statistics, duration_s, n_candidates, seed, vehicle) tuple."""
    return group_cycle(*job)
