"""Positions on the earth as local metres: the one sphere every stage and the virtual truck use."""

from __future__ import annotations

import numpy as np

EARTH_RADIUS_M = 6_371_000.0
"""Mean earth radius [m] of the equirectangular projection (well under 1 m over 100 km)."""


def local_east_north_m(latitude_deg, longitude_deg):
    """Equirectangular east/north [m] around the first finite fix (enough for step lengths)."""
    lat = np.asarray(latitude_deg, dtype=float)
    lon = np.asarray(longitude_deg, dtype=float)
    finite = np.flatnonzero(np.isfinite(lat) & np.isfinite(lon))
    if len(finite) == 0:
        return np.full(lat.shape, np.nan), np.full(lat.shape, np.nan)
    lat0, lon0 = lat[finite[0]], lon[finite[0]]
    north = np.radians(lat - lat0) * EARTH_RADIUS_M
    east = np.radians(lon - lon0) * EARTH_RADIUS_M * np.cos(np.radians(lat0))
    return east, north


def step_lengths_m(latitude_deg, longitude_deg) -> np.ndarray:
    """Lengths [m] of the steps between consecutive positions on the sphere, each with its own
    latitude's scale of longitude (a projection around one point is off by tan φ Δφ far from it)."""
    north = np.radians(np.diff(latitude_deg)) * EARTH_RADIUS_M
    middle = np.radians((latitude_deg[1:] + latitude_deg[:-1]) / 2)
    east = np.radians(np.diff(longitude_deg)) * EARTH_RADIUS_M * np.cos(middle)
    return np.hypot(east, north)
