"""Is a height grid terrain? A file of the right size with the wrong content (random bytes, the
wrong byte order, a GeoTIFF of something else) would otherwise give gradients of hundreds of percent.

Earth's land lies between the Dead Sea shore (-430 m) and Everest (8849 m); SRTM and other DEMs
keep to that range apart from voids. Neighbouring samples of a 1" or 3" grid (30-90 m apart) differ
by metres to tens of metres; a median step of hundreds of metres is noise, not land.
"""

from __future__ import annotations

import numpy as np

from ..errors import UserError

MIN_HEIGHT_M = -500.0
MAX_HEIGHT_M = 9000.0
MAX_OUTSIDE_SHARE = 0.05
"""Share of samples outside the range above which the grid is not a DEM [-]."""
MAX_MEDIAN_STEP_M = 100.0
"""Median height difference between neighbouring samples above which the grid is noise [m]."""


class ImplausibleDemError(UserError):
    pass


def check_heights(heights_m: np.ndarray, source: str) -> np.ndarray:
    """``heights_m`` (NaN = void) if it looks like terrain, else `ImplausibleDemError` naming ``source``."""
    finite = heights_m[np.isfinite(heights_m)]
    if finite.size == 0:
        return heights_m
    outside = float(np.mean((finite < MIN_HEIGHT_M) | (finite > MAX_HEIGHT_M)))
    if outside > MAX_OUTSIDE_SHARE:
        raise ImplausibleDemError(f"{source}: {outside:.0%} of the heights lie outside {MIN_HEIGHT_M:.0f} to "
                                  f"{MAX_HEIGHT_M:.0f} m: not a terrain model (damaged, wrong byte order or "
                                  f"another kind of file); replace the tile")
    step = np.abs(np.diff(heights_m, axis=1))
    step = step[np.isfinite(step)]
    if step.size and float(np.median(step)) > MAX_MEDIAN_STEP_M:
        raise ImplausibleDemError(f"{source}: neighbouring heights differ by {float(np.median(step)):.0f} m "
                                  f"(median): noise, not terrain; replace the tile")
    return heights_m
