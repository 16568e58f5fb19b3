"""Map per log → reduce per vehicle group → a cycle per group, on one process, a local process
pool, or an existing Dask distributed cluster; the same functions (`analysis.fleet.tasks`) and
the same result whichever runs them."""

from __future__ import annotations

import os
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from haulprofile.contract.private_files import restrict_written

from ..checks import repeated_content
from ..errors import UserError
from ..ingest.foreign import SUFFIXES as FOREIGN_SUFFIXES
from ..ingest.logs import MCAP_SUFFIXES
from ..markov import ClassWidths
from ..signals import SIGNALS_SUFFIXES
from ..vehicle import Vehicle
from ..mass.joint import JointSettings
from .road_load import fit_truck
from .statistics import FleetStatistics, LoadBins
from .tasks import LogResult, LogTask, group_cycle_job, map_log, reduce_group

LOG_SUFFIXES = MCAP_SUFFIXES | FOREIGN_SUFFIXES | SIGNALS_SUFFIXES


class FleetError(UserError):
    pass


@dataclass
class Group:
    """One vehicle group: a directory of logs (each one task) and its vehicle."""

    name: str
    log_dir: Path
    vehicle: Vehicle
    logs: list[Path]


@dataclass
class FleetSpec:
    groups: list[Group]
    dem_dir: Path | None = None
    duration_s: float = 1800.0
    n_candidates: int | None = None
    """Monte Carlo pool of each group's refined cycle selection (None: `analyze run`'s default)."""
    seed: int = 0
    widths: ClassWidths = field(default_factory=ClassWidths)
    bins: LoadBins = field(default_factory=LoadBins)
    options: dict = field(default_factory=dict)
    figures: bool = True
    """Each log's gradient and mass figures (some 30 % of the time per log)."""
    known_masses: list[tuple[str, str, int, float]] = field(default_factory=list)
    """Weighed segments (group, log, segment number from 1, kg): each calibrates its group's torque
    gain for every segment of every log of that group (``--known-mass TRUCK:LOG:SEGMENT=KG``)."""

    def __post_init__(self):
        self.dem_dir = Path(self.dem_dir) if self.dem_dir is not None else None

    @classmethod
    def of(cls, log_dirs: list[str | Path], vehicles: list[Vehicle], **settings) -> "FleetSpec":
        """Groups of the log directories; ``vehicles`` one for all or one per directory."""
        log_dirs = [Path(d) for d in log_dirs]
        if not log_dirs:
            raise FleetError("no log directory given: give one directory of logs per vehicle group")
        if len(vehicles) not in (1, len(log_dirs)):
            raise FleetError(f"{len(vehicles)} vehicle files for {len(log_dirs)} log directories: give vehicle_file "
                             f"once for all groups or once per log directory, in the same order")
        vehicles = vehicles * len(log_dirs) if len(vehicles) == 1 else vehicles
        groups, names = [], set()
        for log_dir, vehicle in zip(log_dirs, vehicles):
            name = _unique(log_dir.resolve().name or "group", names)
            groups.append(Group(name, log_dir, vehicle, find_logs(log_dir)))
        return cls(groups, **settings)


def _unique(name: str, taken: set[str]) -> str:
    candidate, n = name, 2
    while candidate in taken:
        candidate, n = f"{name}-{n}", n + 1
    taken.add(candidate)
    return candidate


def find_logs(log_dir: Path) -> list[Path]:
    """Logs (MCAP, foreign CAN logs, signals tables) anywhere under ``log_dir``, sorted by path."""
    if not log_dir.exists():
        raise FleetError(f"log directory {log_dir} not found")
    if not log_dir.is_dir():
        raise FleetError(f"{log_dir} is not a directory: give one directory of logs per vehicle group")
    logs = sorted(p for p in log_dir.rglob("*") if p.is_file() and p.suffix.lower() in LOG_SUFFIXES)
    if not logs:
        raise FleetError(f"{log_dir}: no logs (.mcap, .log/.asc/.blf/.mf4, or signals .csv/.parquet) in this "
                         f"directory; give a directory that holds a vehicle group's logs")
    return logs


@dataclass
class GroupResult:
    name: str
    vehicle: Vehicle
    statistics: FleetStatistics | None
    failed: list[tuple[str, str]]
    cycle: object | None = None
    selection: dict = field(default_factory=dict)
    error: str | None = None
    road_load: dict = field(default_factory=dict)
    """The group's shared c_r and c_d·A, torque gain and masses of all its logs (`fleet.road_load.fit_truck`)."""
    dates: tuple[str, ...] = ()
    """UTC dates on which any of its logs moved (the fleet report's km/day)."""


@dataclass
class FleetResult:
    groups: list[GroupResult]
    executor: str


DASK_CONNECT_TIMEOUT = "20s"
DASK_CONNECT_WAIT_S = 30.0
"""How long to wait for a Dask scheduler's answer [s]: distributed's own timeout does not cover a
port that accepts a connection and never speaks (not a scheduler), which waited for ever."""
DASK_WORKERS_WAIT_S = 60.0
"""How long to wait for a scheduler's first worker [s] (a cluster without workers runs nothing)."""


class SerialExecutor:
    """Each item in this process, in order. ``map`` yields results in the items' order (as every executor)."""

    name = "serial"

    def map(self, fn, items):
        return (fn(item) for item in items)

    def close(self):
        pass


class LocalExecutor:
    """A ``concurrent.futures.ProcessPoolExecutor`` of ``workers`` processes."""

    def __init__(self, workers: int):
        self.name = f"process pool of {workers}"
        self.pool = ProcessPoolExecutor(max_workers=workers)

    def map(self, fn, items):
        return self.pool.map(fn, items)

    def close(self):
        self.pool.shutdown()


class DaskExecutor:
    """An existing Dask distributed cluster at ``address`` (dask is imported only here)."""

    def __init__(self, address: str):
        try:
            from distributed import Client
        except ImportError:
            raise FleetError("a Dask scheduler address needs Dask: pip install 'haulprofile[fleet]'") from None
        hint = "start it with 'dask scheduler' and workers, or give no scheduler address for the local pool"
        outcome: dict = {}

        def connect():
            try:
                outcome["client"] = Client(address, timeout=DASK_CONNECT_TIMEOUT)
            except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread below
                outcome["error"] = exc

        thread = threading.Thread(target=connect, name="dask-connect", daemon=True)
        thread.start()
        thread.join(DASK_CONNECT_WAIT_S)
        if thread.is_alive():
            raise FleetError(f"no Dask scheduler answered at {address} within {DASK_CONNECT_WAIT_S:.0f} s "
                             f"(is it a scheduler's address?); {hint}")
        error = outcome.get("error")
        if isinstance(error, Exception):  # a bad address fails in many ways inside distributed, also under load
            raise FleetError(f"cannot reach the Dask scheduler at {address} ({error}); {hint}") from None
        if error is not None:
            raise error
        self.client = outcome["client"]
        try:
            self.client.wait_for_workers(1, timeout=DASK_WORKERS_WAIT_S)
        except (TimeoutError, OSError) as exc:
            self.client.close()
            raise FleetError(f"the Dask scheduler at {address} has no worker after {DASK_WORKERS_WAIT_S:.0f} s "
                             f"({type(exc).__name__}); start workers with 'dask worker {address}'") from None
        self.name = f"dask {address}"

    def map(self, fn, items):
        items = list(items)
        futures = self.client.map(fn, items, pure=False) if items else []
        return (future.result() for future in futures)

    def close(self):
        self.client.close()


def executor_for(workers: int | None = None, scheduler: str | None = None):
    if scheduler:
        return DaskExecutor(scheduler)
    workers = (os.cpu_count() or 1) if workers is None else workers
    if workers < 1:
        raise FleetError(f"fleet.workers must be at least 1, got {workers}")
    return SerialExecutor() if workers == 1 else LocalExecutor(workers)


def log_out_dir(out_dir: Path, group: Group, log: Path) -> Path:
    return out_dir / group.name / "logs" / log.relative_to(group.log_dir).as_posix().replace("/", "__")


def run_fleet(spec: FleetSpec, out_dir: str | Path, workers: int | None = None, scheduler: str | None = None,
              say: Callable[[str], None] = print, debug: bool = False, progress: bool = False) -> FleetResult:
    """Map every log, reduce per group in path order, generate a cycle per group, write the
    outputs (`analysis.fleet.output`). Raises `FleetError` only when every log failed. With
    ``progress``, a progress bar of the logs on stderr."""
    from .output import write_fleet

    out_dir = Path(out_dir)
    started_ns = time.time_ns() - 1_000_000_000  # file systems with coarse time stamps
    inside_out = out_dir.resolve()
    for group in spec.groups:
        group.logs = [log for log in group.logs if inside_out not in log.resolve().parents]
        if not group.logs:
            raise FleetError(f"{group.log_dir}: no logs outside the output directory {out_dir}")
    flat = [(group, log) for group in spec.groups for log in group.logs]
    repeated = repeated_content([log for _, log in flat], lambda line: print(f"fleet: {line}", file=sys.stderr))
    for group in spec.groups:
        group.logs = [log for i, (owner, log) in enumerate(flat) if owner is group and i not in repeated]
    weighed = known_masses_by_group(spec)
    tasks = [LogTask(log, group.name, group.vehicle, log_out_dir(out_dir, group, log), spec.dem_dir, spec.options,
                     spec.widths, spec.bins, debug, spec.figures, group.log_dir)
             for group in spec.groups for log in group.logs]
    executor = executor_for(workers, scheduler)
    say(f"fleet: {len(tasks)} logs in {len(spec.groups)} group(s) on {executor.name}")
    try:
        results = list(_progress(executor.map(map_log, tasks), len(tasks), progress))
        _say_results(results, say)
        if all(r.statistics is None for r in results):
            first = results[0]
            raise FleetError(f"all {len(results)} logs failed; the first, {first.path}: {first.error}")
        groups = [_reduced(group, [r for r in results if r.group == group.name], weighed.get(group.name, {}),
                           spec.options) for group in spec.groups]
        todo = [g for g in groups if g.statistics is not None]
        cycles = list(executor.map(group_cycle_job, [(g.name, g.statistics, spec.duration_s, spec.n_candidates,
                                                      spec.seed, g.vehicle) for g in todo]))
    finally:
        executor.close()
    for group, cycle in zip(todo, cycles):
        group.cycle, group.selection, group.error = cycle.cycle, cycle.selection, cycle.error
    fleet = FleetResult(groups, executor.name)
    write_fleet(fleet, spec, out_dir, say)
    restrict_written(out_dir, started_ns)  # positions and times: 0640 whatever the umask
    return fleet


def _progress(results, total: int, enabled: bool):
    if not enabled:
        return results
    from tqdm import tqdm

    return tqdm(results, total=total, unit="log", leave=False)


def known_masses_by_group(spec: FleetSpec) -> dict[str, dict[tuple[str, int], float]]:
    """The spec's weighed segments per group name, each log named by its path under the group's
    directory; a `FleetError` naming a truck or log that is not there."""
    out: dict[str, dict[tuple[str, int], float]] = {}
    groups = {group.name: group for group in spec.groups}
    for truck, log, segment, kg in spec.known_masses:
        group = groups.get(truck)
        if group is None:
            raise FleetError(f"known_masses {truck}:{log}:{segment}={kg:g}: no truck (log directory) named {truck!r}; "
                             f"the trucks are {', '.join(groups)}")
        names = [p.relative_to(group.log_dir).as_posix() for p in group.logs]
        matches = [n for n in names if log in (n, Path(n).name, Path(n).stem)]
        if len(matches) != 1:
            raise FleetError(f"known_masses {truck}:{log}:{segment}={kg:g}: {'no' if not matches else 'more than one'} "
                             f"log of {truck} named {log!r} (its logs: {', '.join(names[:5])}"
                             f"{', …' if len(names) > 5 else ''})")
        out.setdefault(truck, {})[(matches[0], segment)] = kg
    return out


def _reduced(group: Group, results: list[LogResult], known: dict, options) -> GroupResult:
    failed = [(str(r.path), r.error) for r in sorted(results, key=lambda r: str(r.path)) if r.statistics is None]
    statistics = reduce_group(results)
    error = None if statistics is not None else f"every one of its {len(results)} logs failed"
    result = GroupResult(group.name, group.vehicle, statistics, failed, error=error,
                         dates=tuple(sorted({d for r in results if r.statistics is not None for d in r.dates})))
    if statistics is not None:
        mass = getattr(options, "mass", None)
        try:
            result.road_load = fit_truck(statistics.road_load_moments, group.vehicle, known,
                                         mass.joint if mass is not None else JointSettings())
        except UserError as exc:
            result.road_load = {"error": str(exc)}
    return result


def _say_results(results: list[LogResult], say) -> None:
    for r in results:
        if r.statistics is None:
            say(f"fleet: {r.path}: FAILED: {r.error}")
        else:
            for note in r.statistics.notes:
                say(f"fleet: {note}")
