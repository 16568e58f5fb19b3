"""Errors a real DEM has, drawn once per drive (sizes from `realism.Realism`, sources in
``docs/virtual-truck.md``).

A DEM cell at (lat, lon) holds: terrain at (lat, lon) minus the misregistration shift, plus a
spatially correlated vertical error (a smooth random field with the level's correlation length),
plus short-range noise (white per cell), plus a canopy offset over forest and a building offset
over town patches; voids (NaN, written as -32768) where a void field exceeds its threshold.
"""

from __future__ import annotations

import zlib
from dataclasses import asdict, dataclass

import numpy as np

from .realism import Realism
from .road import Road
from .terrain import GridField, spectral_surface

VOID_PATCH_M = 300.0
"""Voids come in patches of about this size (radar shadow and layover on steep slopes, water)."""


@dataclass
class DemErrors:
    level: Realism
    shift_east_cells: float
    shift_north_cells: float
    correlated: GridField | None
    voids: GridField | None
    void_threshold: float
    forest: GridField | None
    town: GridField | None
    seed_key: tuple[int, int]

    @classmethod
    def draw(cls, road: Road, level: Realism, terrain_seed: int, seed: int) -> "DemErrors":
        rng = np.random.default_rng(np.random.SeedSequence([terrain_seed, seed, 0xDE4]))
        pad = 6000.0
        e0, e1 = road.east_m.min() - pad, road.east_m.max() + pad
        n0, n1 = road.north_m.min() - pad, road.north_m.max() + pad
        direction = rng.uniform(0, 2 * np.pi)
        shift = level.dem_shift_cells * rng.uniform(0.5, 1.0)
        correlated = None
        if level.dem_correlated_m > 0 and level.dem_correlation_m > 0:
            step = max(level.dem_correlation_m / 6.0, 25.0)
            shape = (int((n1 - n0) / step) + 2, int((e1 - e0) / step) + 2)
            correlated = GridField(e0, n0, step, level.dem_correlated_m
                                   * spectral_surface(rng, shape, step, level.dem_correlation_m, beta=4.0), 0.0)
        voids, threshold = None, np.inf
        if level.dem_void_fraction > 0:
            step = VOID_PATCH_M / 4.0
            shape = (int((n1 - n0) / step) + 2, int((e1 - e0) / step) + 2)
            values = spectral_surface(rng, shape, step, VOID_PATCH_M, beta=4.0)
            voids = GridField(e0, n0, step, values, -1e9)
            threshold = float(np.quantile(values, 1 - level.dem_void_fraction))
        return cls(level, float(shift * np.cos(direction)), float(shift * np.sin(direction)), correlated, voids,
                   threshold, road.forest, road.town, (terrain_seed, seed))

    def dem_heights_m(self, road: Road, latitude_deg, longitude_deg, cell_m: float) -> np.ndarray:
        """DEM values [m] at grid points of cell size ``cell_m`` (NaN = void)."""
        east, north = road.local(latitude_deg, longitude_deg)
        east, north = np.asarray(east, float), np.asarray(north, float)
        shifted_e, shifted_n = east - self.shift_east_cells * cell_m, north - self.shift_north_cells * cell_m
        lat, lon = road.latlon(shifted_e, shifted_n)
        heights = road.terrain_height_m(lat, lon)
        level = self.level
        if self.correlated is not None:
            heights = heights + self.correlated.at(east, north)
        if level.dem_noise_m > 0:
            heights = heights + level.dem_noise_m * self._cell_noise(east, north, cell_m)
        if self.forest is not None and level.dem_canopy_m > 0:
            heights = heights + level.dem_canopy_m * self.forest.at(shifted_e, shifted_n)
        if self.town is not None and level.dem_building_m > 0:
            heights = heights + level.dem_building_m * self.town.at(shifted_e, shifted_n)
        if self.voids is not None:
            heights = np.where(self.voids.at(east, north) > self.void_threshold, np.nan, heights)
        return heights

    def _cell_noise(self, east: np.ndarray, north: np.ndarray, cell_m: float) -> np.ndarray:
        """Unit white noise, the same for a cell however the grid is cut into blocks."""
        ie = np.round(east / cell_m).astype(np.int64)
        jn = np.round(north / cell_m).astype(np.int64)
        key = (ie * 1_000_003 + jn * 7_919 + zlib.crc32(repr(self.seed_key).encode())) & 0xFFFFFFFF
        key = (key ^ (key >> 16)) * 0x45D9F3B & 0xFFFFFFFF
        key = (key ^ (key >> 16)) * 0x45D9F3B & 0xFFFFFFFF
        key = key ^ (key >> 16)
        u1 = (key & 0xFFFF) / 65536.0 + 1.0 / 131072.0
        u2 = (key >> 16) / 65536.0
        return np.sqrt(-2.0 * np.log(u1)) * np.cos(2 * np.pi * u2)

    def sizes(self) -> dict:
        """The injected sizes for the truth file."""
        return {k: v for k, v in asdict(self.level).items() if k.startswith("dem_")} | {
            "dem_shift_east_cells": self.shift_east_cells, "dem_shift_north_cells": self.shift_north_cells}
