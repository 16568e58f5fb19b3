"""A road engineered into natural terrain: grade limits by road class, cuttings, embankments,
bridges and tunnels (the realistic worlds, ``docs/virtual-truck.md``).

The design line follows the ground smoothed over the class's length, is then limited to the
class's maximum grade (the mean of the lower and upper grade-limited envelopes of the smoothed
ground, which is itself grade-limited) and rounded into vertical curves. Where the ground stays
more than `MAX_CUT_M` above the line the road goes through a tunnel, where it falls more than
`MAX_FILL_M` below it crosses a bridge; elsewhere the ground is cut or filled to the road over a
corridor with 2:3 side slopes, and that earthwork is part of the terrain the DEM is written from.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from ..runs import true_runs
from .terrain import GridField

MAX_CUT_M = 20.0
MAX_FILL_M = 15.0
PORTAL_COVER_M = 12.0
"""A tunnel reaches out to where the cover falls below this [m]."""
ABUTMENT_FILL_M = 8.0
"""A bridge reaches out to where the fill is less than this [m]."""
MIN_TUNNEL_M = 80.0
EARTHWORK_M = 3.0
"""Cut or fill beyond this [m] counts as a cutting or an embankment; less is at grade."""
ROAD_HALF_WIDTH_M = 8.0
SIDE_SLOPE = 1.5
"""Horizontal metres per metre of cut or fill (2:3 slopes)."""

STRUCTURES = ("at grade", "cutting", "embankment", "bridge", "tunnel")
AT_GRADE, CUTTING, EMBANKMENT, BRIDGE, TUNNEL = range(5)


def road_class(limit_kmh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maximum grade [%] and design smoothing length [m] by speed limit: motorways and major
    roads (>= 80 km/h) 5 % over 400 m, rural roads (>= 60 km/h) 8 % over 200 m, streets 9 % over 100 m."""
    limit_kmh = np.asarray(limit_kmh, float)
    grade = np.where(limit_kmh >= 80, 5.0, np.where(limit_kmh >= 60, 8.0, 9.0))
    length = np.where(limit_kmh >= 80, 400.0, np.where(limit_kmh >= 60, 200.0, 100.0))
    return grade, length


@numba.njit(cache=True)
def grade_limited(height_m, max_rise_m):
    """Mean of the upper and lower envelopes whose step i -> i+1 is at most ``max_rise_m[i]``."""
    n = len(height_m)
    upper = height_m.copy()
    lower = height_m.copy()
    for i in range(1, n):
        upper[i] = min(upper[i], upper[i - 1] + max_rise_m[i - 1])
        lower[i] = max(lower[i], lower[i - 1] - max_rise_m[i - 1])
    for i in range(n - 2, -1, -1):
        upper[i] = min(upper[i], upper[i + 1] + max_rise_m[i])
        lower[i] = max(lower[i], lower[i + 1] - max_rise_m[i])
    return 0.5 * (upper + lower)


def design_profile(ground_m: np.ndarray, step_m: float, max_grade_pct: np.ndarray, smoothing_m: float) -> np.ndarray:
    """Road height [m] on the route grid from the natural ground along it."""
    smooth = gaussian_filter1d(ground_m, smoothing_m / step_m, mode="nearest")
    margin = 0.9  # the vertical curves below round the limit off; keep under it
    limited = grade_limited(smooth, margin * max_grade_pct / 100.0 * step_m)
    return gaussian_filter1d(limited, 40.0 / step_m, mode="nearest")


def _grow(core: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Extend each run of ``core`` over the adjacent run of ``reach`` it lies in."""
    out = core.copy()
    for start, end in true_runs(reach):
        if core[start:end].any():
            out[start:end] = True
    return out


def classify(cover_m: np.ndarray, step_m: float, forced_tunnel: np.ndarray) -> np.ndarray:
    """Structure code per grid point from the natural cover (ground minus road) [m]."""
    tunnel = _grow(cover_m > MAX_CUT_M, cover_m > PORTAL_COVER_M)
    for start, end in true_runs(tunnel):
        if (end - start) * step_m < MIN_TUNNEL_M:
            tunnel[start:end] = False
    tunnel |= forced_tunnel
    bridge = _grow(cover_m < -MAX_FILL_M, cover_m < -ABUTMENT_FILL_M) & ~tunnel
    out = np.full(cover_m.shape, AT_GRADE, np.int8)
    out[cover_m > EARTHWORK_M] = CUTTING
    out[cover_m < -EARTHWORK_M] = EMBANKMENT
    out[bridge] = BRIDGE
    out[tunnel] = TUNNEL
    return out


def spread(field: GridField, east_m: np.ndarray, north_m: np.ndarray, along: np.ndarray, lateral_m: float,
           reach: float = 3.0) -> None:
    """Add a profile given along a path to the field, fading sideways as exp(-(d/lateral)^2)."""
    tree = cKDTree(np.column_stack([east_m, north_m]))
    rows, cols = field.values.shape
    e0, e1 = east_m.min() - reach * lateral_m, east_m.max() + reach * lateral_m
    n0, n1 = north_m.min() - reach * lateral_m, north_m.max() + reach * lateral_m
    c0, c1 = max(int((e0 - field.east0_m) / field.step_m), 0), min(int((e1 - field.east0_m) / field.step_m) + 1, cols)
    r0, r1 = max(int((n0 - field.north0_m) / field.step_m), 0), min(int((n1 - field.north0_m) / field.step_m) + 1, rows)
    if c0 >= c1 or r0 >= r1:
        return
    grid_n, grid_e = np.meshgrid(field.north0_m + np.arange(r0, r1) * field.step_m,
                                 field.east0_m + np.arange(c0, c1) * field.step_m, indexing="ij")
    d, idx = tree.query(np.column_stack([grid_e.ravel(), grid_n.ravel()]), distance_upper_bound=reach * lateral_m)
    near = np.isfinite(d)
    add = np.zeros(d.shape)
    add[near] = along[idx[near]] * np.exp(-(d[near] / lateral_m) ** 2)
    field.values[r0:r1, c0:c1] += add.reshape(grid_e.shape)


def earthworks(field: GridField, east_m: np.ndarray, north_m: np.ndarray, road_m: np.ndarray,
               structure: np.ndarray, every: int = 2) -> None:
    """Cut or fill the field to the road in a corridor (road half width plus 2:3 side slopes)
    wherever the road is at grade, in a cutting or on an embankment."""
    keep = (structure != BRIDGE) & (structure != TUNNEL)
    pick = np.flatnonzero(keep)[::every]
    if len(pick) == 0:
        return
    tree = cKDTree(np.column_stack([east_m[pick], north_m[pick]]))
    reach = ROAD_HALF_WIDTH_M + SIDE_SLOPE * MAX_CUT_M + field.step_m
    rows, cols = field.values.shape
    c = np.clip(((east_m[pick] - field.east0_m) / field.step_m).astype(int), 0, cols - 1)
    r = np.clip(((north_m[pick] - field.north0_m) / field.step_m).astype(int), 0, rows - 1)
    pad = int(np.ceil(reach / field.step_m)) + 1
    mask = np.zeros((rows, cols), bool)
    for dr in range(-pad, pad + 1):
        for dc in range(-pad, pad + 1):
            mask[np.clip(r + dr, 0, rows - 1), np.clip(c + dc, 0, cols - 1)] = True
    cells = np.argwhere(mask)
    ce = field.east0_m + cells[:, 1] * field.step_m
    cn = field.north0_m + cells[:, 0] * field.step_m
    d, idx = tree.query(np.column_stack([ce, cn]), distance_upper_bound=reach)
    near = np.isfinite(d)
    cells, d, idx = cells[near], d[near], idx[near]
    old = field.values[cells[:, 0], cells[:, 1]]
    road = road_m[pick][idx]
    width = ROAD_HALF_WIDTH_M + SIDE_SLOPE * np.abs(old - road)
    weight = np.clip((width - d) / np.maximum(width - ROAD_HALF_WIDTH_M, 1e-6), 0.0, 1.0)
    field.values[cells[:, 0], cells[:, 1]] = old + weight * (road - old)
