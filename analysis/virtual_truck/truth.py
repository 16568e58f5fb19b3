"""Ground truth beside a virtual log, so that every estimate and every failure can be explained:
the road on a 10 m grid, the mass per segment and the size of every injected error."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from ..signals import write_signals
from .dem import dem_errors
from .road_design import STRUCTURES, TUNNEL

GRID_SPACING_M = 10.0


def structure_codes(road) -> np.ndarray:
    """Structure code per road grid point (`road_design.STRUCTURES`; the ideal world knows only tunnels)."""
    if road.structure is not None:
        return road.structure
    return np.where(road.in_tunnel, TUNNEL, 0).astype(np.int8)


def truth_grid(virtual, spacing_m: float = GRID_SPACING_M) -> pd.DataFrame:
    """The road per ``spacing_m`` bin of true distance: mean gradient over the bin (100 dh/ds),
    height and terrain at its centre, the structure covering most of it."""
    road = virtual.road
    start = np.arange(0.0, road.length_m - spacing_m + 1e-9, spacing_m)
    centre = start + spacing_m / 2
    height = road.at(road.height_m, centre)
    gradient = 100.0 * (road.at(road.height_m, start + spacing_m) - road.at(road.height_m, start)) / spacing_m
    codes = structure_codes(road)
    per_bin = codes[: len(start) * int(spacing_m)].reshape(len(start), int(spacing_m))
    majority = np.array([np.bincount(row, minlength=len(STRUCTURES)).argmax() for row in per_bin])
    lat, lon = road.latlon(road.at(road.east_m, centre), road.at(road.north_m, centre))
    frame = pd.DataFrame({"distance_m": start, "road_height_m": height, "gradient_pct": gradient,
                          "terrain_height_m": road.terrain_height_m(lat, lon),
                          "structure": np.array(STRUCTURES)[majority]})
    if road.natural_cover_m is not None:
        frame["natural_cover_m"] = road.at(road.natural_cover_m, centre)
    return frame


def truth_segments(truth: pd.DataFrame) -> pd.DataFrame:
    """Runs of constant true mass: start, end [s] and mass [kg]."""
    mass = truth["mass_kg"].to_numpy()
    time_s = truth["time_s"].to_numpy()
    change = np.flatnonzero(np.diff(mass) != 0) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(mass)]]) - 1
    return pd.DataFrame({"start_s": time_s[starts], "end_s": time_s[ends], "mass_kg": mass[starts]})


def injected_errors(virtual) -> dict:
    """Realism level, seed and the size of every injected error (world, DEM, sensors)."""
    out = {"scenario": virtual.scenario.name, "vehicle": virtual.vehicle.name, "seed": virtual.seed,
           "realism_level": virtual.realism.level}
    out |= {k: v for k, v in virtual.injected.items() if k != "seed"}
    errors = dem_errors(virtual)
    if errors is not None:
        out |= errors.sizes()
    return out


def write_truth(virtual, directory: str | Path) -> list[Path]:
    """``truth.parquet`` (10 Hz), ``truth-road-10m.csv``, ``truth-mass.csv``, ``truth-errors.json``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = [write_signals(virtual.truth, directory / "truth.parquet")]
    for name, frame in (("truth-road-10m.csv", truth_grid(virtual)), ("truth-mass.csv", truth_segments(virtual.truth))):
        frame.to_csv(directory / name, index=False, float_format="%.4f")
        paths.append(directory / name)
    path = directory / "truth-errors.json"
    path.write_text(json.dumps(injected_errors(virtual), indent=1, default=float) + "\n")
    return paths + [path]
