"""The virtual truck's terrain as real SRTM ``.hgt`` tiles (3 arc-second, 1201 x 1201)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..dem.srtm import SAMPLES_PER_SIDE, tile_name, tile_origin, write_hgt
from .road import Road, build_road
from .scenario import Scenario

ARC_SECONDS = 3
MARGIN_DEG = 0.05
"""Tiles within this margin around the route are written too (~5 km)."""
_ROWS_PER_BLOCK = 100


def route_tiles(road: Road, margin_deg: float = MARGIN_DEG) -> list[str]:
    """Names of the tiles the route (plus margin) touches."""
    lat, lon = road.latlon(road.east_m, road.north_m)
    lats = range(math.floor(lat.min() - margin_deg), math.floor(lat.max() + margin_deg) + 1)
    lons = range(math.floor(lon.min() - margin_deg), math.floor(lon.max() + margin_deg) + 1)
    return [tile_name(a, o) for a in lats for o in lons]


def tile_heights_m(road: Road, name: str) -> np.ndarray:
    """Terrain heights [m] on a tile's grid (row 0 = north), unrounded."""
    lat0, lon0 = tile_origin(name)
    side = SAMPLES_PER_SIDE[ARC_SECONDS]
    lats = lat0 + 1.0 - np.arange(side) / (side - 1)
    lons = lon0 + np.arange(side) / (side - 1)
    heights = np.empty((side, side))
    for start in range(0, side, _ROWS_PER_BLOCK):
        rows = lats[start:start + _ROWS_PER_BLOCK]
        grid_lat, grid_lon = np.meshgrid(rows, lons, indexing="ij")
        heights[start:start + len(rows)] = road.terrain_height_m(grid_lat, grid_lon)
    return heights


def write_dem(drive_or_scenario, directory: str | Path, seed: int = 0) -> list[Path]:
    """Write every tile the route touches (plus a margin) into ``directory``; return the paths.

    Heights are rounded to whole metres as SRTM stores them. A `Scenario` is built with ``seed``;
    a `VirtualDrive` uses its own world.
    """
    road = build_road(drive_or_scenario, seed) if isinstance(drive_or_scenario, Scenario) else drive_or_scenario.road
    directory = Path(directory)
    return [write_hgt(directory / f"{name}.hgt", tile_heights_m(road, name)) for name in route_tiles(road)]
