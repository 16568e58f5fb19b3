"""Digital elevation models read from local files (never downloaded at run time).

`open_dem(directory)` picks the reader: SRTM ``.hgt`` tiles (`srtm.SrtmDem`) or GeoTIFF rasters
(`geotiff.GeoTiffDem`, needs the optional rasterio). Both offer ``height_m(lat, lon)`` [m].
"""

from __future__ import annotations

from pathlib import Path

from ..errors import UserError
from .srtm import MissingTileError, SrtmDem

__all__ = ["open_dem", "MissingTileError", "SrtmDem"]


def open_dem(directory: str | Path):
    """The DEM in ``directory``: SRTM tiles if any ``.hgt`` is there, else GeoTIFFs.

    Parameters
    ----------
    directory : str or Path
        Folder of SRTM ``.hgt`` tiles (1″ or 3″) or GeoTIFF rasters; nothing is downloaded.

    Returns
    -------
    SrtmDem or GeoTiffDem
        ``.height_m(latitude_deg, longitude_deg)`` → terrain height [m]; a position outside the
        tiles raises `MissingTileError` naming the tile.

    References
    ----------
    The map-matching height of paper equation (5).
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise UserError(f"DEM directory {directory} not found (give a folder of SRTM .hgt tiles or GeoTIFFs)")
    suffixes = {p.suffix.lower() for p in directory.iterdir()}
    if ".hgt" in suffixes:
        return SrtmDem(directory)
    if suffixes & {".tif", ".tiff"}:
        from .geotiff import GeoTiffDem
        return GeoTiffDem(directory)
    raise UserError(f"DEM directory {directory} holds no SRTM .hgt tiles and no GeoTIFF (.tif) files")
