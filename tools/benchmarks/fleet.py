"""Fleet runner: 50 one-hour virtual-truck MCAP logs in two vehicle groups, map → reduce → cycle per
group, with 1 local worker (in-process, serial) against 2 local worker processes.

Logs: 25 ``urban-delivery`` drives of the rigid-18t (≈ 60 min each) and 25 ``long-haul`` drives of
the tractor-40t (≈ 52 min each), seeds 0…24, each started at its own place (2° apart) so that all
drives' terrain tiles go into one DEM directory without overlapping. Generated once into
``.bench-cache/fleet/``. ``--quick``: 6 drives of the urban route's first ten minutes.

The speed-up is serial time / 2-worker time (above 1 means the pool is faster), each the fastest of
`REPEATS` alternating runs; each run's CPU time gives the share of a core it got. The benchmark
fails unless every run's reduced transition counts, histograms, totals and cycles equal the first
serial run's.
"""

from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path

from bench import result

CACHE = Path(__file__).resolve().parents[2] / ".bench-cache" / "fleet"
REPEATS = 2
"""Runs of each kind, alternating; the fastest of each counts (the machine is shared)."""
GROUPS = {"urban-rigid-18t": ("urban-delivery", "rigid-18t"), "long-haul-tractor-40t": ("long-haul", "tractor-40t")}


def fleet_inputs(quick: bool) -> tuple[list[Path], list[str], Path]:
    """(group directories, vehicle names, DEM directory), generated on first use."""
    from haulprofile.testing.fleet import virtual_fleet

    group_dirs, dem_dir = virtual_fleet(CACHE / ("quick" if quick else "full"), GROUPS, 3 if quick else 25,
                                        n_sections=5 if quick else None, workers=os.cpu_count() or 1,
                                        say=lambda msg: print(f"fleet benchmark: {msg}", flush=True))
    return group_dirs, [vehicle for _, vehicle in GROUPS.values()], dem_dir


def _cpu_s() -> float:
    """CPU time of this process and its finished children [s]."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _run(group_dirs, vehicles, dem_dir, out_dir: Path, workers: int, candidates: int):
    """(wall time [s], CPU time of this process and its workers [s], the fleet result)."""
    from haulprofile.analysis.fleet import FleetSpec, run_fleet
    from haulprofile.analysis.vehicle import load_vehicle

    spec = FleetSpec.of(group_dirs, [load_vehicle(v) for v in vehicles], dem_dir=dem_dir,
                        n_candidates=candidates, seed=0)
    cpu, start = _cpu_s(), time.perf_counter()
    fleet = run_fleet(spec, out_dir, workers=workers, say=lambda _msg: None)
    return time.perf_counter() - start, _cpu_s() - cpu, fleet


def _warm_up(group_dirs, vehicles, dem_dir, out_dir: Path) -> None:
    """One log per group through map and cycle in this process, untimed: imports, numba caches and
    the DEM reader are loaded before either timed run (the pool's workers fork from this process)."""
    from haulprofile.analysis.fleet import LogTask, group_cycle, map_log
    from haulprofile.analysis.vehicle import load_vehicle

    for group_dir, vehicle in zip(group_dirs, vehicles):
        log = sorted(group_dir.glob("*.mcap"))[0]
        result = map_log(LogTask(log, group_dir.name, load_vehicle(vehicle), out_dir / group_dir.name, dem_dir))
        group_cycle(group_dir.name, result.statistics, 600.0, 100, 0)


def _check_same(serial, pooled) -> None:
    for a, b in zip(serial.groups, pooled.groups):
        if not a.statistics.same_as(b.statistics):
            raise AssertionError(f"group {a.name}: the 2-worker run's reduced statistics differ from the serial run's")
        if not a.cycle.equals(b.cycle):
            raise AssertionError(f"group {a.name}: the 2-worker run chose another cycle than the serial run")


def bench_fleet(quick: bool) -> list[dict]:
    group_dirs, vehicles, dem_dir = fleet_inputs(quick)
    _warm_up(group_dirs, vehicles, dem_dir, CACHE / "warm-up")
    n_logs = sum(len(list(d.glob("*.mcap"))) for d in group_dirs)
    candidates = 1000 if quick else 10_000
    out = CACHE / ("quick" if quick else "full") / "out"
    runs = {1: [], 2: []}
    for _ in range(REPEATS):
        for workers in (1, 2):
            runs[workers].append(_run(group_dirs, vehicles, dem_dir, out / f"workers-{workers}", workers, candidates))
    serial = runs[1][0][2]
    for _, _, pooled in runs[1][1:] + runs[2]:
        _check_same(serial, pooled)
    serial_s, serial_cpu_s, _ = min(runs[1], key=lambda run: run[0])
    pool_s, pool_cpu_s, _ = min(runs[2], key=lambda run: run[0])
    failed = sum(len(g.failed) for g in serial.groups)
    hours = sum(g.statistics.totals["duration_s"] for g in serial.groups) / 3600
    transitions = sum(int(g.statistics.counts.count.sum()) for g in serial.groups)
    # Share of a core each run got (1 = a whole core per worker): below 1, other processes took the rest.
    serial_share, pool_share = serial_cpu_s / serial_s, pool_cpu_s / (2 * pool_s)
    print(json.dumps({"fleet": {"logs": n_logs, "failed": failed, "hours": round(hours, 2),
                                "transitions": transitions, "walls_1_s": [r[0] for r in runs[1]],
                                "walls_2_s": [r[0] for r in runs[2]], "serial_s": serial_s,
                                "serial_cpu_s": serial_cpu_s, "pool_2_s": pool_s, "pool_2_cpu_s": pool_cpu_s,
                                "serial_core_share": serial_share, "pool_2_core_share_per_worker": pool_share}}),
          flush=True)
    return [result(f"fleet: {n_logs} logs ({hours:.1f} h), 2 local workers, best of {REPEATS}; "
                   f"ratio = speed-up over 1", pool_s, "s", peer="1 worker (serial, in-process)",
                   peer_value=serial_s, counts_equal_serial=True, failed_logs=failed,
                   serial_core_share=round(serial_share, 3), pool_core_share_per_worker=round(pool_share, 3))]


BENCHMARKS = [bench_fleet]
