"""GeoTIFF elevation models (e.g. Copernicus GLO-30, national LiDAR DEMs) read with rasterio.

rasterio is an optional extra (``pip install haulprofile[geotiff]``) imported on first use. Every
``*.tif``/``*.tiff`` in the directory is one raster; a point is looked up in the first raster that
covers it, after transforming WGS84 longitude/latitude into the raster's CRS. Pixel values are
heights [m] at pixel centres; the nodata value is a void.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import UserError
from .bilinear import bilinear_m
from .plausible import check_heights
from .srtm import MissingTileError

GEOTIFF_SUFFIXES = (".tif", ".tiff")


def _rasterio():
    try:
        import rasterio
        import rasterio.warp
    except ImportError:
        raise UserError("reading GeoTIFF DEMs needs rasterio: pip install 'haulprofile[geotiff]'") from None
    return rasterio


MAX_PIXELS = 200_000_000
"""Most pixels of one raster read whole (1.6 GB of float64 heights): a 25 m DEM of 350 x 350 km,
checked from the file's header before any is read (a 6.5 MB GeoTIFF may declare 40000²)."""


class GeoTiffDem:
    """A directory of GeoTIFF rasters; each is read into memory on first use and kept."""

    def __init__(self, directory: str | Path):
        self.directory = Path(directory)
        if not self.directory.is_dir():
            raise UserError(f"DEM directory {self.directory} not found")
        self.paths = sorted(p for p in self.directory.iterdir() if p.suffix.lower() in GEOTIFF_SUFFIXES)
        if not self.paths:
            raise UserError(f"no GeoTIFF (.tif) files in DEM directory {self.directory}")
        rasterio = _rasterio()
        self._meta = []
        for path in self.paths:
            try:
                with rasterio.open(path) as src:
                    if src.crs is None:
                        raise UserError(f"{path}: GeoTIFF without a coordinate reference system (CRS); its "
                                        "pixels cannot be placed (set one, e.g. gdal_edit.py -a_srs EPSG:4326)")
                    if src.width * src.height > MAX_PIXELS:
                        raise UserError(f"{path}: {src.width} x {src.height} pixels, more than {MAX_PIXELS:,} "
                                        f"(~{MAX_PIXELS * 8 / 1e9:.0f} GB as heights); cut it to the route's area "
                                        "(gdal_translate -projwin)")
                    self._meta.append((src.crs, src.transform, src.bounds, src.nodata))
            except rasterio.errors.RasterioIOError as exc:
                raise UserError(f"{path}: not a readable GeoTIFF ({exc})") from None
        self._grids: dict[int, np.ndarray] = {}

    def _grid(self, index: int) -> np.ndarray:
        if index not in self._grids:
            rasterio = _rasterio()
            with rasterio.open(self.paths[index]) as src:
                grid = src.read(1).astype(np.float64)
                if src.nodata is not None:
                    grid[grid == src.nodata] = np.nan
                grid[grid <= -32767] = np.nan
            self._grids[index] = check_heights(grid, str(self.paths[index]))
        return self._grids[index]

    def height_m(self, latitude_deg, longitude_deg) -> np.ndarray:
        """Bilinearly interpolated height [m] at each point (voids left out, NaN positions give NaN);
        `MissingTileError` naming the first uncovered point when the route leaves every raster."""
        rasterio = _rasterio()
        lat = np.atleast_1d(np.asarray(latitude_deg, dtype=float))
        lon = np.atleast_1d(np.asarray(longitude_deg, dtype=float))
        out = np.full(lat.shape, np.nan)
        todo = np.isfinite(lat) & np.isfinite(lon)
        for index, (crs, transform, bounds, _) in enumerate(self._meta):
            if not todo.any():
                break
            x, y = lon[todo], lat[todo]
            if crs is not None and not crs.is_geographic:
                x, y = (np.asarray(v) for v in rasterio.warp.transform("EPSG:4326", crs, x, y))
            inverse = ~transform
            col, row = inverse @ (x, y)
            col, row = np.asarray(col) - 0.5, np.asarray(row) - 0.5
            grid_shape = self._grid(index).shape
            covered = (row >= -0.5) & (row <= grid_shape[0] - 0.5) & (col >= -0.5) & (col <= grid_shape[1] - 0.5)
            if not covered.any():
                continue
            grid = self._grid(index)
            values = bilinear_m(grid, np.clip(row[covered], 0, grid.shape[0] - 1),
                                np.clip(col[covered], 0, grid.shape[1] - 1))
            where = np.flatnonzero(todo)[covered]
            out[where] = values
            todo[where] = False
        if todo.any():
            k = np.flatnonzero(todo)[0]
            raise MissingTileError(
                f"the route leaves the DEM at {lat[k]:.5f} N, {lon[k]:.5f} E: no GeoTIFF in "
                f"{self.directory} covers it (add a raster for that area)")
        return out
