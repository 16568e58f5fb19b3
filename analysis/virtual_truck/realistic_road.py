"""The realistic levels' road: natural terrain first, the road engineered into it (`road_design`)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from ..runs import true_runs
from . import road_design as eng
from .road import GRID_STEP_M, KMH_PER_MPS, Road, _path, route_grid
from .scenario import Scenario, ScenarioFileError
from .terrain import cover_fraction_field, natural_terrain

TERRAIN_STEP_M = 25.0
VDRI_TRACKING_M = 500.0
"""For a VECTO cycle the terrain is bent to the cycle's road over this smoothing length."""


def _limit_kmh(distance: np.ndarray, breaks: np.ndarray) -> np.ndarray:
    index = np.clip(np.searchsorted(breaks[:, 0], distance, side="right") - 1, 0, len(breaks) - 1)
    return breaks[index, 1] * KMH_PER_MPS


def _depth_in(structure_mask: np.ndarray, distance: np.ndarray) -> np.ndarray:
    depth = np.zeros(distance.shape)
    for start, end in true_runs(structure_mask):
        d = distance[start:end]
        depth[start:end] = np.minimum(d - distance[start], distance[end - 1] - d)
    return depth


def engineered_road(scenario: Scenario, seed: int = 0) -> Road:
    """The world of a scenario for a seed at the realistic levels (same seed, same world)."""
    rng = np.random.default_rng(np.random.SeedSequence([scenario.terrain.seed, seed, 0x7E22]))
    breaks, stops, length, distance, target = route_grid(scenario, seed)
    east, north, _, curvature = _path(scenario, distance, rng)

    terrain = scenario.terrain
    relief = max(terrain.hill_amplitude_m, terrain.offroad_hill_amplitude_m)
    field = natural_terrain(rng, (east.min(), east.max(), north.min(), north.max()), relief,
                            terrain.base_altitude_m, step_m=TERRAIN_STEP_M,
                            longest_m=max(terrain.hill_wavelengths_m))
    urban = float(np.mean(_limit_kmh(distance, breaks) < 60.0))
    forest = cover_fraction_field(rng, field, 0.35 * (1.0 - urban))
    town = cover_fraction_field(rng, field, 0.1 + 0.6 * urban, patch_m=1000.0)
    ground = field.at(east, north)
    limit = _limit_kmh(distance, breaks)
    max_grade, smoothing = eng.road_class(np.full(limit.shape, np.median(limit)))
    if scenario.route.vdri:
        from .road import _height_profile
        height, _ = _height_profile(scenario, distance, rng)
        bend = gaussian_filter1d(height - ground, VDRI_TRACKING_M / GRID_STEP_M, mode="nearest")
        eng.spread(field, east[::10], north[::10], bend[::10], 1500.0)
        ground = field.at(east, north)
    else:
        height = eng.design_profile(ground, GRID_STEP_M, max_grade, float(np.median(smoothing)))

    forced = np.zeros(distance.shape, bool)
    for tunnel in scenario.tunnel:
        end = tunnel.start_m + tunnel.length_m
        if end > length:
            raise ScenarioFileError(f"tunnel at {tunnel.start_m:g} m ends after the route ({length:g} m)")
        inside = (distance >= tunnel.start_m) & (distance <= end)
        forced |= inside
        u = np.clip((distance - tunnel.start_m) / tunnel.length_m, 0.0, 1.0)
        hill = np.where(inside, np.maximum(height + tunnel.depth_m * np.sin(np.pi * u) ** 2 - ground, 0.0), 0.0)
        near = np.abs(distance - (tunnel.start_m + end) / 2) <= tunnel.length_m
        eng.spread(field, east[near][::5], north[near][::5], hill[near][::5], 0.4 * tunnel.length_m)
    ground = field.at(east, north)
    natural_cover = ground - height
    structure = eng.classify(natural_cover, GRID_STEP_M, forced)
    eng.earthworks(field, east, north, height, structure)
    cover = field.at(east, north) - height
    in_tunnel = structure == eng.TUNNEL
    gradient = 100.0 * np.gradient(height, distance)
    return Road(
        distance_m=distance, target_speed_mps=target, height_m=height, gradient_pct=gradient,
        cut_fill_m=np.where(in_tunnel, 0.0, cover), tunnel_cover_m=np.where(in_tunnel, cover, 0.0),
        in_tunnel=in_tunnel, tunnel_depth_in_m=_depth_in(in_tunnel, distance),
        east_m=east, north_m=north, curvature_per_m=curvature,
        stop_distance_m=np.array([d for d, _ in stops]), stop_duration_s=np.array([t for _, t in stops]),
        start_latitude_deg=scenario.start_latitude_deg, start_longitude_deg=scenario.start_longitude_deg,
        hills=np.zeros((0, 4)), tunnel_lateral_m=np.zeros(distance.shape), initial_stop_s=scenario.route.initial_stop_s,
        base_altitude_m=float(np.mean(height)), structure=structure, natural_cover_m=natural_cover,
        terrain=field, forest=forest, town=town)
