"""SRTM ``.hgt`` tiles: read, write and bilinear interpolation at GPS fixes.

A tile ``N50E006.hgt`` covers latitude 50..51 deg N and longitude 6..7 deg E. It is a square grid of
big-endian int16 heights [m], 3601 x 3601 samples (1 arc-second) or 1201 x 1201 (3 arc-second), rows
from north to south, columns from west to east; edges are shared with the neighbouring tiles.
-32768 marks a void.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import UserError
from .bilinear import bilinear_m
from .plausible import check_heights

VOID = -32768
SAMPLES_PER_SIDE = {1: 3601, 3: 1201}


class MissingTileError(UserError):
    pass


def tile_name(latitude_deg: float, longitude_deg: float) -> str:
    """Name of the tile holding a point, e.g. ``N50E006``."""
    lat, lon = math.floor(latitude_deg), math.floor(longitude_deg)
    return f"{'N' if lat >= 0 else 'S'}{abs(lat):02d}{'E' if lon >= 0 else 'W'}{abs(lon):03d}"


def tile_origin(name: str) -> tuple[int, int]:
    """South-west corner (lat, lon) of a tile name."""
    lat = int(name[1:3]) * (1 if name[0] in "Nn" else -1)
    lon = int(name[4:7]) * (1 if name[3] in "Ee" else -1)
    return lat, lon


def read_hgt(path: str | Path) -> np.ndarray:
    """Heights [m] of one tile as float64, voids as NaN, row 0 = northern edge."""
    raw = np.fromfile(path, dtype=">i2")
    side = int(round(math.sqrt(raw.size)))
    if side * side != raw.size or side not in SAMPLES_PER_SIDE.values():
        raise UserError(f"{path}: {raw.size * 2} bytes is not an SRTM tile (1201² or 3601² samples)")
    heights = raw.reshape(side, side).astype(np.float64)
    heights[raw.reshape(side, side) == VOID] = np.nan
    return check_heights(heights, str(path))


def write_hgt(path: str | Path, heights_m: np.ndarray) -> Path:
    """Write a tile from heights [m] (row 0 = north; NaN becomes void), rounded to whole metres."""
    heights_m = np.asarray(heights_m, dtype=float)
    if heights_m.shape[0] != heights_m.shape[1] or heights_m.shape[0] not in SAMPLES_PER_SIDE.values():
        raise ValueError(f"an SRTM tile is 1201x1201 or 3601x3601, got {heights_m.shape}")
    raw = np.where(np.isfinite(heights_m), np.rint(heights_m), VOID).astype(">i2")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    raw.tofile(path)
    return path


class SrtmDem:
    """A directory of ``.hgt`` tiles; tiles are loaded on first use and kept."""

    def __init__(self, directory: str | Path):
        self.directory = Path(directory)
        if not self.directory.is_dir():
            raise UserError(f"DEM directory {self.directory} not found")
        self._tiles: dict[str, np.ndarray] = {}

    def tile(self, name: str) -> np.ndarray:
        if name not in self._tiles:
            candidates = [self.directory / f"{name}.hgt", self.directory / f"{name.lower()}.hgt"]
            path = next((p for p in candidates if p.is_file()), None)
            if path is None:
                raise MissingTileError(
                    f"the route leaves the DEM: tile {name}.hgt is missing in {self.directory} "
                    f"(add the SRTM tile for that area)")
            self._tiles[name] = read_hgt(path)
        return self._tiles[name]

    def height_m(self, latitude_deg, longitude_deg) -> np.ndarray:
        """Bilinearly interpolated terrain height [m] at each point (1" and 3" tiles alike); void
        corners are left out of the interpolation, NaN where all four are voids or the position
        is NaN. Raises `MissingTileError` naming the tile when a point lies outside the DEM."""
        lat = np.atleast_1d(np.asarray(latitude_deg, dtype=float))
        lon = np.atleast_1d(np.asarray(longitude_deg, dtype=float))
        out = np.full(lat.shape, np.nan)
        ok = np.isfinite(lat) & np.isfinite(lon)
        lat0 = np.floor(lat[ok]).astype(int)
        lon0 = np.floor(lon[ok]).astype(int)
        keys = lat0 * 1000 + lon0
        values = np.full(keys.shape, np.nan)
        for key in np.unique(keys):
            sel = keys == key
            tlat, tlon = int(lat0[sel][0]), int(lon0[sel][0])
            grid = self.tile(tile_name(tlat, tlon))
            n = grid.shape[0] - 1
            row = (tlat + 1 - lat[ok][sel]) * n
            col = (lon[ok][sel] - tlon) * n
            values[sel] = bilinear_m(grid, row, col)
        out[ok] = values
        return out
