"""The virtual truck's terrain as a DEM: SRTM ``.hgt`` tiles (3" or 1") or a GeoTIFF (25 m, UTM).

In the ideal world the tiles hold the terrain as it is. At the realistic levels they hold what a
real DEM holds (`DemErrors`, sizes and sources in ``docs/virtual-truck.md``): the terrain plus a
spatially correlated vertical error, short-range noise, canopy over forest and buildings over
town patches, sampled with a horizontal misregistration, with voids.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..dem.srtm import SAMPLES_PER_SIDE, tile_name, tile_origin, write_hgt
from ..errors import UserError
from .dem_errors import DemErrors
from .road import Road
from .world import build_road
from .scenario import Scenario

ARC_SECONDS = 3
MARGIN_DEG = 0.05
"""Tiles within this margin around the route are written too (~5 km)."""
GEOTIFF_STEP_M = 25.0
GEOTIFF_MARGIN_M = 3000.0
VOID = -32768
_ROWS_PER_BLOCK = 100


def route_tiles(road: Road, margin_deg: float = MARGIN_DEG) -> list[str]:
    """Names of the tiles the route (plus margin) touches."""
    lat, lon = road.latlon(road.east_m, road.north_m)
    lats = range(math.floor(lat.min() - margin_deg), math.floor(lat.max() + margin_deg) + 1)
    lons = range(math.floor(lon.min() - margin_deg), math.floor(lon.max() + margin_deg) + 1)
    return [tile_name(a, o) for a in lats for o in lons]


def _heights(road: Road, lat: np.ndarray, lon: np.ndarray, errors: DemErrors | None, cell_m: float) -> np.ndarray:
    if errors is None:
        return road.terrain_height_m(lat, lon)
    return errors.dem_heights_m(road, lat, lon, cell_m)


def tile_heights_m(road: Road, name: str, errors: DemErrors | None = None,
                   arc_seconds: int = ARC_SECONDS) -> np.ndarray:
    """Heights [m] on a tile's grid (row 0 = north), unrounded; NaN for voids."""
    lat0, lon0 = tile_origin(name)
    side = SAMPLES_PER_SIDE[arc_seconds]
    lats = lat0 + 1.0 - np.arange(side) / (side - 1)
    lons = lon0 + np.arange(side) / (side - 1)
    cell_m = arc_seconds / 3600.0 * math.radians(1.0) * 6_371_000.0
    heights = np.empty((side, side))
    block = _ROWS_PER_BLOCK if arc_seconds == 3 else _ROWS_PER_BLOCK // 3
    for start in range(0, side, block):
        rows = lats[start:start + block]
        grid_lat, grid_lon = np.meshgrid(rows, lons, indexing="ij")
        heights[start:start + len(rows)] = _heights(road, grid_lat, grid_lon, errors, cell_m)
    return heights


def _world(drive_or_scenario, seed: int):
    if isinstance(drive_or_scenario, Scenario):
        return build_road(drive_or_scenario, seed, drive_or_scenario.realism), drive_or_scenario.realism, seed, \
            drive_or_scenario.terrain.seed
    return (drive_or_scenario.road, drive_or_scenario.realism, drive_or_scenario.seed,
            drive_or_scenario.scenario.terrain.seed)


def dem_errors(drive_or_scenario, seed: int = 0) -> DemErrors | None:
    """The DEM errors of a drive's world (None at the ideal level)."""
    road, level, seed, terrain_seed = _world(drive_or_scenario, seed)
    return None if level.is_ideal else DemErrors.draw(road, level, terrain_seed, seed)


def write_dem(drive_or_scenario, directory: str | Path, seed: int = 0, arc_seconds: int = ARC_SECONDS,
              fmt: str = "hgt") -> list[Path]:
    """Write the DEM of a drive's world into ``directory``; return the paths.

    ``fmt`` ``hgt``: every SRTM tile the route touches (plus a margin) at ``arc_seconds`` 3 or 1,
    heights rounded to whole metres as SRTM stores them, voids -32768. ``geotiff``: one 25 m
    raster in the route's UTM zone (needs rasterio). A `Scenario` is built with ``seed`` at its
    own realism level; a `VirtualDrive` uses its own world and level.
    """
    road, _, _, _ = _world(drive_or_scenario, seed)
    errors = dem_errors(drive_or_scenario, seed)
    directory = Path(directory)
    if fmt == "geotiff":
        return [write_geotiff(road, directory / "terrain.tif", errors)]
    if fmt != "hgt":
        raise UserError(f"unknown DEM format {fmt!r} (hgt or geotiff)")
    if arc_seconds not in SAMPLES_PER_SIDE:
        raise UserError(f"SRTM tiles are 1 or 3 arc-seconds, not {arc_seconds}")
    return [write_hgt(directory / f"{name}.hgt", tile_heights_m(road, name, errors, arc_seconds))
            for name in route_tiles(road)]


def write_geotiff(road: Road, path: str | Path, errors: DemErrors | None = None,
                  step_m: float = GEOTIFF_STEP_M) -> Path:
    """A GeoTIFF of the terrain around the route: ``step_m`` pixels in the route's UTM zone
    (WGS84, EPSG:326xx/327xx), float32 heights, nodata -32768 for voids."""
    try:
        import rasterio
        import rasterio.warp
        from rasterio.transform import from_origin
    except ImportError:
        raise UserError("writing GeoTIFF DEMs needs rasterio: pip install 'haulprofile[geotiff]'") from None
    lat, lon = road.latlon(road.east_m, road.north_m)
    zone = int((lon[0] + 180.0) // 6) + 1
    crs = f"EPSG:{32600 + zone if lat[0] >= 0 else 32700 + zone}"
    x, y = (np.asarray(v) for v in rasterio.warp.transform("EPSG:4326", crs, lon, lat))
    x0 = math.floor((x.min() - GEOTIFF_MARGIN_M) / step_m) * step_m
    y1 = math.ceil((y.max() + GEOTIFF_MARGIN_M) / step_m) * step_m
    cols = int(math.ceil((x.max() + GEOTIFF_MARGIN_M - x0) / step_m))
    rows = int(math.ceil((y1 - (y.min() - GEOTIFF_MARGIN_M)) / step_m))
    heights = np.empty((rows, cols), np.float32)
    centres_x = x0 + (np.arange(cols) + 0.5) * step_m
    for start in range(0, rows, _ROWS_PER_BLOCK):
        centres_y = y1 - (np.arange(start, min(start + _ROWS_PER_BLOCK, rows)) + 0.5) * step_m
        gx, gy = np.meshgrid(centres_x, centres_y)
        glon, glat = (np.asarray(v).reshape(gx.shape)
                      for v in rasterio.warp.transform(crs, "EPSG:4326", gx.ravel(), gy.ravel()))
        block = _heights(road, glat, glon, errors, step_m)
        heights[start:start + len(centres_y)] = np.where(np.isfinite(block), block, VOID)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with rasterio.open(path, "w", driver="GTiff", height=rows, width=cols, count=1, dtype="float32", crs=crs,
                       transform=from_origin(x0, y1, step_m, step_m), nodata=VOID, compress="deflate") as dst:
        dst.write(heights, 1)
    return path
