"""The road the virtual truck drives (`Road`): route (target speed, stops), road height, horizontal
path and the terrain around it, and the ideal world's road (`ideal_road`).

Everything is a function of the driven distance s [m] on a 1 m grid, except the terrain, which is a
field over (latitude, longitude). In the ideal world (`ideal_road` here) it is built so that along
the route it lies exactly ``cut_fill`` above the road, and in a tunnel up to ``depth_m`` above it;
the realistic levels build the terrain first and the road into it (`realistic_road`). Away from the road seeded Gaussian hills rise
smoothly, so a 3 arc-second DEM represents the field well. Horizontal positions use a local
equirectangular projection around the start point (good to well under 1 m over 100 km).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .. import vecto
from ..geodesy import EARTH_RADIUS_M
from .scenario import Scenario, ScenarioFileError
from .terrain import GridField

GRID_STEP_M = 1.0
KMH_PER_MPS = 3.6
_KD_STEP = 10
"""Route points every 10 m in the nearest-point search (refined by projection on segments)."""
_EXACT_WITHIN_M = 3000.0
ROAD_INFLUENCE_M = 1500.0
"""The road's height profile fades into the surrounding base level over about this distance."""
OFFROAD_RISE_M = 1000.0
"""Off-road hills rise from zero at the road to full height over about this distance."""


@dataclass
class Road:
    """Route and terrain on a 1 m distance grid (index = distance in metres)."""

    distance_m: np.ndarray
    target_speed_mps: np.ndarray
    height_m: np.ndarray
    gradient_pct: np.ndarray
    cut_fill_m: np.ndarray
    """Terrain above the road outside tunnels [m] (cuttings > 0, embankments < 0)."""
    tunnel_cover_m: np.ndarray
    """Terrain above the road inside tunnels [m]."""
    in_tunnel: np.ndarray
    tunnel_depth_in_m: np.ndarray
    """Distance to the nearer portal inside a tunnel, 0 outside [m]."""
    east_m: np.ndarray
    north_m: np.ndarray
    curvature_per_m: np.ndarray
    stop_distance_m: np.ndarray
    stop_duration_s: np.ndarray
    start_latitude_deg: float
    start_longitude_deg: float
    hills: np.ndarray
    """Off-road Gaussian hills: rows (east_m, north_m, sigma_m, amplitude_m)."""
    tunnel_lateral_m: np.ndarray
    initial_stop_s: float
    base_altitude_m: float
    structure: np.ndarray | None = None
    """Structure code per grid point (`road_design.STRUCTURES`), None in the ideal world."""
    natural_cover_m: np.ndarray | None = None
    """Natural ground minus road before earthworks [m] (cutting depth > 0, fill height < 0)."""
    terrain: GridField | None = None
    """The terrain surface of a realistic world (with earthworks and tunnel hills)."""
    forest: GridField | None = None
    town: GridField | None = None

    @property
    def cover_m(self) -> np.ndarray:
        """Terrain height minus road height along the route [m]."""
        return self.cut_fill_m + self.tunnel_cover_m

    @property
    def length_m(self) -> float:
        return float(self.distance_m[-1])

    def at(self, values: np.ndarray, distance_m) -> np.ndarray:
        """Linear interpolation of a grid array at distances [m]."""
        return np.interp(distance_m, self.distance_m, values)

    def latlon(self, east_m, north_m) -> tuple[np.ndarray, np.ndarray]:
        lat = self.start_latitude_deg + np.degrees(np.asarray(north_m) / EARTH_RADIUS_M)
        lon = self.start_longitude_deg + np.degrees(
            np.asarray(east_m) / (EARTH_RADIUS_M * np.cos(np.radians(self.start_latitude_deg))))
        return lat, lon

    def local(self, latitude_deg, longitude_deg) -> tuple[np.ndarray, np.ndarray]:
        north = np.radians(np.asarray(latitude_deg) - self.start_latitude_deg) * EARTH_RADIUS_M
        east = (np.radians(np.asarray(longitude_deg) - self.start_longitude_deg)
                * EARTH_RADIUS_M * np.cos(np.radians(self.start_latitude_deg)))
        return east, north

    def terrain_height_m(self, latitude_deg, longitude_deg) -> np.ndarray:
        """Terrain height [m] at any position: road + cover at the nearest route point, tunnel
        cover fading sideways, off-road hills rising with the distance from the road."""
        east, north = self.local(latitude_deg, longitude_deg)
        if self.terrain is not None:
            return self.terrain.at(east, north)
        shape = np.shape(east)
        east, north = np.ravel(east), np.ravel(north)
        s, d = self.nearest(east, north)
        cut = self.at(self.cut_fill_m, s)
        lateral = np.maximum(self.at(self.tunnel_lateral_m, s), 1.0)
        tunnel = self.at(self.tunnel_cover_m, s) * np.exp(-(d / lateral) ** 2)
        road = (self.at(self.height_m, s) + np.minimum(s, 0.0) * self.gradient_pct[0] / 100
                + np.maximum(s - self.length_m, 0.0) * self.gradient_pct[-1] / 100)
        along = road + cut + tunnel
        fade = np.exp(-(d / ROAD_INFLUENCE_M) ** 2)
        offroad = (1.0 - np.exp(-(d / OFFROAD_RISE_M) ** 2)) * self._hills(east, north)
        return (fade * along + (1.0 - fade) * self.base_altitude_m + offroad).reshape(shape)

    def _hills(self, east: np.ndarray, north: np.ndarray) -> np.ndarray:
        out = np.zeros_like(east)
        for e0, n0, sigma, amp in self.hills:
            out += amp * np.exp(-((east - e0) ** 2 + (north - n0) ** 2) / (2 * sigma * sigma))
        return out

    def nearest(self, east: np.ndarray, north: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance along the route [m] of the nearest route point, and the distance to it [m]
        (exact within `_EXACT_WITHIN_M` of the route, within a factor 2 beyond). Beyond its ends
        the route continues straight: s < 0 before the start, s > length after the end."""
        if not hasattr(self, "_tree"):
            self._tree = cKDTree(np.column_stack([self.east_m[::_KD_STEP], self.north_m[::_KD_STEP]]))
        points = np.column_stack([east, north])
        approx, idx = self._tree.query(points, eps=1.0)
        near = approx < 2 * _EXACT_WITHIN_M
        idx[near] = self._tree.query(points[near])[1]
        best_s = np.zeros_like(east)
        best_d = np.full_like(east, np.inf)
        last = len(self.distance_m) - 1
        for shift in (-1, 0):
            i0 = np.clip((idx + shift) * _KD_STEP, 0, last)
            i1 = np.clip(i0 + _KD_STEP, 0, last)
            ex, ny = self.east_m[i1] - self.east_m[i0], self.north_m[i1] - self.north_m[i0]
            seg2 = np.maximum(ex * ex + ny * ny, 1e-12)
            u = ((east - self.east_m[i0]) * ex + (north - self.north_m[i0]) * ny) / seg2
            u = np.clip(u, np.where(i0 == 0, -np.inf, 0.0), np.where(i1 == last, np.inf, 1.0))
            pe, pn = self.east_m[i0] + u * ex, self.north_m[i0] + u * ny
            d = np.hypot(east - pe, north - pn)
            better = d < best_d
            best_d = np.where(better, d, best_d)
            best_s = np.where(better, self.distance_m[i0] + u * (self.distance_m[i1] - self.distance_m[i0]), best_s)
        return best_s, best_d


def _sections(scenario: Scenario) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Breakpoints (distance, speed) and stops (distance, duration) of a generated or VECTO route."""
    route = scenario.route
    if route.vdri:
        cycle = vecto.read_vdri(scenario.base_dir / route.vdri)
        moving = cycle["target_speed_mps"].to_numpy() > 0
        if not moving.any():
            raise ScenarioFileError(f"{route.vdri}: the cycle never moves (all target speeds are 0)")
        breaks = np.column_stack([cycle["distance_m"].to_numpy()[moving], cycle["target_speed_mps"].to_numpy()[moving]])
        stops = [(float(d), float(t)) for d, v, t in zip(cycle["distance_m"], cycle["target_speed_mps"],
                                                          cycle["stop_time_s"]) if v == 0 and t > 0 and d > 0]
        end = float(cycle["distance_m"].iloc[-1])
        breaks[0, 0] = 0.0
    else:
        breaks, stops, position = [], [], 0.0
        for section in route.section:
            breaks.append((position, section.speed_kmh / KMH_PER_MPS))
            position += section.length_m
            if section.stop_s > 0:
                stops.append((position, section.stop_s))
        breaks, end = np.array(breaks), position
    stops = [(d, t) for d, t in stops if d < end - 1.0] + [(end, route.final_stop_s)]
    return np.vstack([breaks, [end, breaks[-1, 1]]]), stops


def _height_profile(scenario: Scenario, distance: np.ndarray, rng: np.random.Generator):
    """Road height [m] and gradient [%] (eq. 5: 100 dh/ds) on the grid."""
    terrain = scenario.terrain
    if scenario.route.vdri:
        cycle = vecto.read_vdri(scenario.base_dir / scenario.route.vdri)
        gradient = np.interp(distance, cycle["distance_m"], cycle["gradient_pct"])
        steps = 0.5 * (gradient[1:] + gradient[:-1]) / 100.0 * np.diff(distance)
        height = terrain.base_altitude_m + np.concatenate([[0.0], np.cumsum(steps)])
        return height, gradient
    wavelengths = np.asarray(terrain.hill_wavelengths_m)
    weights = wavelengths / wavelengths.max()
    phases = rng.uniform(0, 2 * np.pi, len(wavelengths))
    k = 2 * np.pi / wavelengths
    amp = terrain.hill_amplitude_m * weights
    height = terrain.base_altitude_m + np.sum(amp[:, None] * np.sin(k[:, None] * distance + phases[:, None]), axis=0)
    gradient = 100.0 * np.sum((amp * k)[:, None] * np.cos(k[:, None] * distance + phases[:, None]), axis=0)
    return height, gradient


def traffic_factor(distance: np.ndarray, traffic: float, rng: np.random.Generator) -> np.ndarray:
    """Share of the speed limit the traffic allows [-]: seeded dips (a slower vehicle ahead, a
    junction) about every 1.5 km of 10-45 % over 60-250 m, on a +-3 % wander; 1 where traffic = 0."""
    length = distance[-1]
    n_dips = rng.poisson(length / 1500.0)
    centres = rng.uniform(0, length, n_dips)
    depths = rng.uniform(0.10, 0.45, n_dips)
    widths = rng.uniform(60.0, 250.0, n_dips)
    wavelength, phase = rng.uniform(400.0, 1200.0), rng.uniform(0, 2 * np.pi)
    dips = np.zeros_like(distance)
    for centre, depth, width in zip(centres, depths, widths):
        near = np.abs(distance - centre) < 5 * width
        dips[near] = np.maximum(dips[near], depth * np.exp(-0.5 * ((distance[near] - centre) / width) ** 2))
    wander = 0.03 * (np.sin(2 * np.pi * distance / wavelength + phase) - 1.0) / 2.0
    return np.clip(1.0 - traffic * (dips - wander), 0.3, 1.0)


def _allowed_speed(distance: np.ndarray, breaks: np.ndarray, decel_mps2: float,
                   factor: np.ndarray | float = 1.0) -> np.ndarray:
    """Target speed [m/s] with look-ahead: never above what braking at ``decel`` allows before a
    lower limit further on (a backward pass, v_i = min(v_i, sqrt(v_{i+1}^2 + 2 b ds)))."""
    index = np.searchsorted(breaks[:, 0], distance, side="right") - 1
    limit = breaks[np.clip(index, 0, len(breaks) - 1), 1] * factor
    allowed = limit.copy()
    for i in range(len(allowed) - 2, -1, -1):
        allowed[i] = min(allowed[i], np.sqrt(allowed[i + 1] ** 2 + 2.0 * decel_mps2 * GRID_STEP_M))
    return allowed


def _path(scenario: Scenario, distance: np.ndarray, rng: np.random.Generator):
    """East, north [m], heading [rad from east] and curvature [1/m] of the route's gently curving path."""
    n_turns = 3
    turn_wavelengths = rng.uniform(4000.0, 15000.0, n_turns)
    turn_phases = rng.uniform(0, 2 * np.pi, n_turns)
    amp = np.radians(scenario.terrain.curviness_deg) / n_turns
    k = 2 * np.pi / turn_wavelengths
    heading = np.radians(90.0 - scenario.start_heading_deg) + np.sum(
        amp * np.sin(k[:, None] * distance + turn_phases[:, None]) - amp * np.sin(turn_phases)[:, None], axis=0)
    curvature = np.sum((amp * k)[:, None] * np.cos(k[:, None] * distance + turn_phases[:, None]), axis=0)
    east = np.concatenate([[0.0], np.cumsum(np.cos(0.5 * (heading[1:] + heading[:-1])) * np.diff(distance))])
    north = np.concatenate([[0.0], np.cumsum(np.sin(0.5 * (heading[1:] + heading[:-1])) * np.diff(distance))])

    return east, north, heading, curvature


def route_grid(scenario: Scenario, seed: int = 0):
    """The route on its distance grid, the same at every realism level: section breaks, stops
    (distance [m], duration [s]), length [m], grid distance [m] and the speed the road and its
    traffic allow [m/s]."""
    breaks, stops = _sections(scenario)
    length = breaks[-1, 0]
    distance = np.arange(0.0, np.floor(length / GRID_STEP_M) * GRID_STEP_M + GRID_STEP_M, GRID_STEP_M)
    traffic_rng = np.random.default_rng(np.random.SeedSequence([scenario.terrain.seed, seed, 0x7AFF]))
    factor = traffic_factor(distance, scenario.driver.traffic, traffic_rng)
    target = _allowed_speed(distance, breaks, 0.8 * scenario.driver.comfort_decel_mps2, factor)
    return breaks, stops, length, distance, target


def ideal_road(scenario: Scenario, seed: int = 0) -> Road:
    """The ideal world of a scenario for a seed (same seed, same world): terrain built around the road."""
    rng = np.random.default_rng(np.random.SeedSequence([scenario.terrain.seed, seed, 0x70AD]))
    breaks, stops, length, distance, target = route_grid(scenario, seed)
    height, gradient = _height_profile(scenario, distance, rng)

    cut_wavelengths = np.array([350.0, 800.0, 1700.0])
    cut_phases = rng.uniform(0, 2 * np.pi, 3)
    cut = scenario.terrain.cut_fill_m / 3 * np.sum(
        np.sin(2 * np.pi * distance[None, :] / cut_wavelengths[:, None] + cut_phases[:, None]), axis=0)
    in_tunnel = np.zeros(distance.shape, bool)
    depth_in = np.zeros(distance.shape)
    tunnel_cover = np.zeros(distance.shape)
    lateral = np.zeros(distance.shape)
    for tunnel in scenario.tunnel:
        end = tunnel.start_m + tunnel.length_m
        if end > length:
            raise ScenarioFileError(f"tunnel at {tunnel.start_m:g} m ends after the route ({length:g} m)")
        inside = (distance >= tunnel.start_m) & (distance <= end)
        u = (distance[inside] - tunnel.start_m) / tunnel.length_m
        in_tunnel |= inside
        depth_in[inside] = np.minimum(distance[inside] - tunnel.start_m, end - distance[inside])
        tunnel_cover[inside] = tunnel.depth_m * np.sin(np.pi * u) ** 2
        near = np.abs(distance - (tunnel.start_m + end) / 2) <= tunnel.length_m
        lateral[near] = 0.4 * tunnel.length_m
    cut *= (1.0 - np.exp(-(distance / 150.0) ** 2)) * (1.0 - np.exp(-((length - distance) / 150.0) ** 2))
    for tunnel in scenario.tunnel:
        outside = np.maximum(tunnel.start_m - distance, distance - tunnel.start_m - tunnel.length_m)
        cut *= 1.0 - np.exp(-(np.maximum(outside, 0.0) / 150.0) ** 2)

    east, north, heading, curvature = _path(scenario, distance, rng)

    pad = 8000.0
    area_km2 = (np.ptp(east) + 2 * pad) * (np.ptp(north) + 2 * pad) / 1e6
    n_hills = int(np.clip(area_km2 / 25.0, 4, 400))
    hills = np.column_stack([
        rng.uniform(east.min() - pad, east.max() + pad, n_hills),
        rng.uniform(north.min() - pad, north.max() + pad, n_hills),
        rng.uniform(800.0, 2500.0, n_hills),
        rng.uniform(-0.5, 1.0, n_hills) * scenario.terrain.offroad_hill_amplitude_m,
    ])
    road = Road(
        distance_m=distance, target_speed_mps=target, height_m=height, gradient_pct=gradient,
        cut_fill_m=cut, tunnel_cover_m=tunnel_cover, in_tunnel=in_tunnel, tunnel_depth_in_m=depth_in,
        east_m=east, north_m=north, curvature_per_m=curvature,
        stop_distance_m=np.array([d for d, _ in stops]), stop_duration_s=np.array([t for _, t in stops]),
        start_latitude_deg=scenario.start_latitude_deg, start_longitude_deg=scenario.start_longitude_deg,
        hills=hills, tunnel_lateral_m=lateral, initial_stop_s=scenario.route.initial_stop_s,
        base_altitude_m=float(np.mean(height)))
    return road
