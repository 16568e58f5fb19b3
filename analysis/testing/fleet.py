"""Virtual-truck fleets for tests and the benchmark: many seeded drives as MCAP logs, one directory
per vehicle group, and one DEM directory holding every drive's terrain."""

from __future__ import annotations

import dataclasses
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

SPACING_DEG = 2.0
"""Drives start this far apart, so no two drives' terrain tiles overlap in the shared DEM."""


def placed(scenario, index: int, n_sections: int | None = None):
    """``scenario`` started in its own 2° square (index 0…89), keeping its first ``n_sections``."""
    route = scenario.route if n_sections is None else dataclasses.replace(
        scenario.route, section=scenario.route.section[:n_sections])
    return dataclasses.replace(scenario, route=route, start_latitude_deg=30.5 + SPACING_DEG * (index % 10),
                               start_longitude_deg=0.5 + SPACING_DEG * (index // 10))


def write_drive(job: tuple) -> Path:
    """One drive: (scenario name or file, vehicle name or file, place index, seed, sections kept or
    None, log path, DEM directory[, realism level, the truck's torque-report gain, truth directory])
    → the log's path. With a gain, the level's per-drive random torque gain is replaced by the
    truck's fixed one (a property of its engine calibration, the same in every log), and the
    true mass per segment goes to ``<truth directory>/<log stem>-mass.csv``."""
    from haulprofile.analysis.vehicle import load_vehicle
    from haulprofile.analysis.virtual_truck import drive, load_scenario, realism_level, write_dem, write_mcap
    from haulprofile.analysis.virtual_truck.truth import truth_segments

    scenario_name, vehicle_name, index, seed, n_sections, log_path, dem_dir, *more = job
    level, gain, truth_dir = (*more, None, None, None)[:3]
    if gain is not None:
        level = realism_level(level or "ideal", torque_gain_pct=0.0)
    truck = drive(placed(load_scenario(scenario_name), index, n_sections), load_vehicle(vehicle_name), seed=seed,
                  realism=level)
    if gain is not None:
        engine = truck.sensors["engine"]
        engine["actual_engine_torque_pct"] = np.clip(np.round(engine["actual_engine_torque_pct"] * gain), -125, 125)
        truck.injected["torque_report_gain"] = gain - 1.0
    if truth_dir is not None:
        Path(truth_dir).mkdir(parents=True, exist_ok=True)
        truth_segments(truck.truth).to_csv(Path(truth_dir) / f"{Path(log_path).stem}-mass.csv", index=False)
    write_dem(truck, dem_dir)
    write_mcap(truck, log_path)
    return Path(log_path)


def virtual_fleet(root: str | Path, groups: dict[str, tuple[str, str]], drives_per_group: int,
                  n_sections: int | None = None, workers: int = 1, say=print, realism: str | None = None,
                  torque_gains: dict[str, float] | None = None) -> tuple[list[Path], Path]:
    """Write ``drives_per_group`` seeded drives (seeds 0, 1, …) per group ``name → (scenario,
    vehicle)`` into ``root/<name>/drive-NN.mcap`` and their terrain into ``root/dem``; logs that
    exist are kept. ``realism``: the level of every drive (None: the scenario's); ``torque_gains``
    {group: gain}: that group is one truck whose torque report is off by this factor in every
    log, its true masses per segment in ``root/truth/<group>/``. Returns (group directories, DEM
    directory)."""
    root = Path(root)
    dem_dir = root / "dem"
    dem_dir.mkdir(parents=True, exist_ok=True)
    jobs, group_dirs = [], []
    for g, (group, (scenario_name, vehicle_name)) in enumerate(groups.items()):
        group_dir = root / group
        group_dir.mkdir(parents=True, exist_ok=True)
        group_dirs.append(group_dir)
        for seed in range(drives_per_group):
            log_path = group_dir / f"drive-{seed:02d}.mcap"
            if not log_path.exists():
                gain = (torque_gains or {}).get(group)
                jobs.append((scenario_name, vehicle_name, g * drives_per_group + seed, seed, n_sections,
                             str(log_path), str(dem_dir), realism, gain,
                             None if gain is None else str(root / "truth" / group)))
    if workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for path in pool.map(write_drive, jobs):
                say(f"wrote {path}")
    else:
        for job in jobs:
            say(f"wrote {write_drive(job)}")
    return group_dirs, dem_dir
