"""Road gradient (paper §2.2.1, equations (5)-(8)): map-matching on a DEM, barometric height,
IMU, and their accuracy-weighted fusion on a distance grid.

Public: `estimate_gradient(frame, dem, settings) -> GradientResult`, `GradientSettings`, and the
pipeline `stage(ctx)` which adds ``height_m``, ``gradient_pct`` and each source's columns.
"""

from __future__ import annotations

import numpy as np

from ..dem import MissingTileError, open_dem
from ..dem.plausible import ImplausibleDemError
from ..errors import UserError
from .estimate import GradientResult, GradientSettings, estimate_gradient
from .figure import draw_sources

__all__ = ["estimate_gradient", "GradientResult", "GradientSettings", "stage", "gradient_with_dem_fallback"]


def gradient_with_dem_fallback(frame, dem_dir, settings: GradientSettings = GradientSettings(), say=print):
    """`estimate_gradient` with the DEM in ``dem_dir`` (if given); when the route leaves the DEM the
    reason is said and the estimate falls back to the barometer alone."""
    dem = open_dem(dem_dir) if dem_dir is not None else None
    try:
        return estimate_gradient(frame, dem, settings)
    except (MissingTileError, ImplausibleDemError) as exc:
        say(f"gradient: {exc}; using the barometer alone")
        return estimate_gradient(frame, None, settings)


def stage(ctx) -> None:
    frame = ctx.signals
    if ctx.dem_dir is None:
        ctx.say("gradient: no --dem DIR given: barometric height only (no map-matching)")
    settings = GradientSettings(**ctx.options.get("gradient", {}))
    try:
        result = estimate_gradient(frame, open_dem(ctx.dem_dir) if ctx.dem_dir is not None else None, settings)
    except (MissingTileError, ImplausibleDemError) as exc:
        raise type(exc)(f"{exc}; or run without --dem for barometric height only") from None
    except UserError as exc:
        ctx.say(f"gradient: skipped: {exc}")
        return
    for note in result.notes:
        ctx.say(f"gradient: {note}")
    for name, values in result.samples.items():
        frame[name] = values
    grid = result.grid
    grid.to_csv(ctx.out_dir / "gradient.csv", index=False)
    files = ["gradient.csv"]
    if ctx.figures:
        files.append(draw_sources(grid, ctx.out_dir / "gradient.png").name)
    gradient = grid["gradient_pct"].to_numpy()
    ctx.summary["gradient"] = {
        "grid_spacing_m": settings.spacing_m,
        "sources": [s for s, c in (("map", "gradient_map_pct"), ("baro", "gradient_baro_pct"),
                                   ("imu", "gradient_imu_pct")) if c in grid.columns],
        "mean_map_weight": float(np.mean(grid["weight_map"])),
        "map_sigma_m": result.map_sigma_m,
        "gradient_pct": {"mean": float(np.nanmean(gradient)), "min": float(np.nanmin(gradient)),
                         "max": float(np.nanmax(gradient))},
        "height_gain_m": float(np.sum(np.clip(np.diff(grid["height_m"].to_numpy()), 0, None))),
        "notes": result.notes,
        "files": files,
    }
