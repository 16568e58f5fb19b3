"""The accuracy matrix (``python tools/bench.py accuracy``): seeded virtual drives (urban,
regional, long-haul; tunnels, bridges, cuttings, payload and trailer changes) at the three realism
levels through the real analysis (MCAP log -> ingest -> gradient -> mass), scored against the
truth. One JSON line per vehicle file (exact / datasheet-mismatched), level and gradient method:
gradient RMSE [%-pt] on the 10 m grid per road category (median and p95 over drives) and the mass
error per segment (median and worst of |error| over all segments, LS, RLS and ``mass_kg``, the
joint estimate, with the share of segments whose truth is inside its stated ±2σ and the RMS of
their error over their stated σ, ``rms_z`` (1 where σ is honest); and
``mass_kg_weighed``, the other segments with the first one weighed), and for the
smoother the share of 10 m bins whose true gradient is inside its stated ±2σ. Each drive is
analysed with each sensor set (`SENSOR_SETS`: the full log and the same log without barometer,
IMU or GPS); lines of a set other than ``full`` have it in their name and ``sensor_set``. Drives
run in a process pool of 2 workers.

``ACCURACY_SEEDS=4-7`` (or ``4,5,6,7``) draws the drives from other seeds: the same scenarios, roads,
weather and errors never seen while the estimator was tuned on seeds 0-3; their per-drive results
go to ``accuracy-seeds-4-7.json`` beside the default's."""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from bench import CACHE_DIR, result
from haulprofile.testing.accuracy import CATEGORIES, MASS_KEYS, METHODS, SENSOR_SETS, Case, run_case

LEVELS = ("ideal", "typical", "harsh")
WORKERS = 2


def seeds_from(text: str | None) -> tuple[int, ...] | None:
    """The seeds named by ``ACCURACY_SEEDS`` ("4-7" or "4,5,6,7"), None where it is unset or empty."""
    if not text or not text.strip():
        return None
    seeds = []
    for part in text.split(","):
        first, _, last = part.strip().partition("-")
        seeds += range(int(first), int(last or first) + 1)
    return tuple(seeds)


def matrix(quick: bool, seeds: tuple[int, ...] | None = None) -> list[Case]:
    """36 drives (quick: 6): per level, urban 8 km, regional 16 km with its tunnel and delivery,
    long-haul 15 km with a 10-minute stop (trailer change at typical/harsh); DEM as 3" SRTM
    tiles, one in four drives as a 25 m GeoTIFF and one in six as 1" tiles. ``seeds`` replaces the
    default seeds (0-3; quick: 0)."""
    shapes = [("urban-delivery", 8000.0, 0.0), ("regional-tunnel", 16000.0, 0.0), ("long-haul", 15000.0, 600.0)]
    seeds = seeds or ((0,) if quick else (0, 1, 2, 3))
    cases = []
    for level in LEVELS if not quick else ("ideal", "typical"):
        for seed in seeds:
            for k, (name, length, stop) in enumerate(shapes):
                index = len(cases)
                dem = "geotiff" if index % 4 == 3 else "hgt1" if index % 6 == 5 else "hgt3"
                cases.append(Case(name, level, seed, length, stop, "hgt3" if quick else dem))
    return cases


def _stats(values: list[float]) -> dict:
    values = [v for v in values if v is not None]
    if not values:
        return {"median": None, "p95": None, "drives": 0}
    return {"median": float(np.median(values)), "p95": float(np.percentile(values, 95)), "drives": len(values)}


def summarise(results: list[dict]) -> list[dict]:
    """One line per vehicle file, level, sensor set and method; the ``full`` set's lines keep
    the names they had before sensor sets were an axis."""
    lines = []
    for sensor_set in SENSOR_SETS:
        runs = [r["sensor_sets"][sensor_set] | {"case": r["case"]} for r in results
                if sensor_set in r.get("sensor_sets", {})]
        lines += _summarise_set(runs, sensor_set)
    return lines


def _summarise_set(results: list[dict], sensor_set: str) -> list[dict]:
    lines = []
    prefix = "" if sensor_set == "full" else f"{sensor_set}_"
    for vehicle in ("exact", "datasheet"):
        for level in LEVELS:
            runs = [r for r in results if r["case"]["level"] == level]
            if not runs:
                continue
            for method in METHODS:
                have = [r for r in runs if method in r["gradient"]]
                name = f"accuracy_{level}_{prefix}{method}_{vehicle}_vehicle"
                if not have and sensor_set != "full":
                    continue
                if not have:
                    lines.append(result(name, None, "%-pt", available=False, level=level, method=method,
                                        vehicle=vehicle, column=METHODS[method],
                                        note="the gradient stage writes no such column"))
                    continue
                gradient = {cat: _stats([r["gradient"][method][cat] for r in have]) for cat in CATEGORIES}
                mass = {}
                for key in MASS_KEYS:
                    errors = [abs(e) for r in have if r["mass"] for e in r["mass"][vehicle][method].get(key, [])]
                    mass[key] = {"segments": len(errors)}
                    if errors:
                        mass[key] |= {"median_pct": 100 * float(np.median(errors)),
                                      "worst_pct": 100 * float(np.max(errors))}
                for key in ("mass_kg", "mass_kg_weighed"):
                    covered = [c for r in have if r["mass"]
                               for c in r["mass"][vehicle][method].get(f"{key}_within_2_sigma", [])]
                    if covered:
                        mass[key]["within_2_sigma"] = float(np.mean(covered))
                    z = [v for r in have if r["mass"] for v in r["mass"][vehicle][method].get(f"{key}_z", [])
                         if v is not None]
                    if z:
                        mass[key]["rms_z"] = float(np.sqrt(np.mean(np.square(z))))
                covered = [r["gradient_within_2_sigma"].get(method) for r in have]
                covered = [c for c in covered if c is not None]
                coverage = {"median": float(np.median(covered)), "min": float(np.min(covered))} if covered else None
                lines.append(result(name, gradient["outside"]["median"], "%-pt", available=True, level=level,
                                    sensor_set=sensor_set, method=method, vehicle=vehicle, column=METHODS[method],
                                    drives=len(have), gradient_rmse_pct=gradient, gradient_within_2_sigma=coverage,
                                    mass_error=mass))
    return lines


def bench_accuracy_matrix(quick: bool):
    seeds = seeds_from(os.environ.get("ACCURACY_SEEDS"))
    cases = matrix(quick, seeds)
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=WORKERS) as pool:
        results = list(pool.map(run_case, cases))
    elapsed = time.perf_counter() - started
    suffix = ("-quick" if quick else "") + (f"-seeds-{os.environ['ACCURACY_SEEDS'].strip()}" if seeds else "")
    (CACHE_DIR / f"accuracy{suffix}.json").write_text(json.dumps(results, indent=1))
    return summarise(results) + [result("accuracy_matrix_wall_time", elapsed, "s", drives=len(cases),
                                        workers=WORKERS, load_average_1min=os.getloadavg()[0])]


BENCHMARKS = [bench_accuracy_matrix]
