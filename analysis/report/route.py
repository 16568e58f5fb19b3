"""Report chapter on the route: the positions over a hillshade of the run's own elevation model,
coloured by the estimated gradient, with the stretches where the smoother gated the map out.

Offline by design: no tile server, no network; the background is the DEM the gradient stage read.
Positions the logger never wrote (privacy zones) stay gaps, and with ``private`` the chapter draws
nothing, since a map is a position however its axes are labelled.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..geodesy import step_lengths_m
from .html import Section

TITLE = "The route"
GAP_M = 200.0
"""Consecutive positions further apart than this [m] (a privacy zone, a GPS outage) are not joined."""
GRID = 320
"""Hillshade cells along the longer side of the map."""
M_PER_DEG = 111_320.0


def _track(signals: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """(latitude, longitude, gradient [%], distance [m]) of the samples with a position."""
    if not {"latitude_deg", "longitude_deg"} <= set(signals.columns):
        return None
    lat, lon = signals["latitude_deg"].to_numpy(float), signals["longitude_deg"].to_numpy(float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if ok.sum() < 2:
        return None
    gradient = (signals["gradient_pct"].to_numpy(float) if "gradient_pct" in signals
                else np.full(len(signals), np.nan))
    distance = signals["distance_m"].to_numpy(float) if "distance_m" in signals else np.arange(len(signals), dtype=float)
    return lat[ok], lon[ok], gradient[ok], distance[ok]


def _segments(lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Line segments between consecutive positions in (lon, lat), and which of them join (not a gap)."""
    points = np.column_stack([lon, lat])
    segments = np.stack([points[:-1], points[1:]], axis=1)
    return segments, step_lengths_m(lat, lon) <= GAP_M


def hillshade(dem, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, tuple[float, float, float, float]] | None:
    """Shaded relief [0, 1] of ``dem`` over the route's box (a margin of a tenth of its size, kept
    within the tiles the route lies on) and its extent (west, east, south, north); None where the
    DEM holds no height there."""
    from matplotlib.colors import LightSource

    from ..dem import MissingTileError

    margin = 0.1 * max(np.ptp(lat), np.ptp(lon), 0.005)
    south = max(lat.min() - margin, np.floor(lat.min()))
    north = min(lat.max() + margin, np.ceil(lat.max()) - 1e-9)
    west = max(lon.min() - margin, np.floor(lon.min()))
    east = min(lon.max() + margin, np.ceil(lon.max()) - 1e-9)
    aspect = (east - west) * np.cos(np.radians(0.5 * (south + north))) / (north - south)
    nx, ny = (GRID, max(int(GRID / aspect), 20)) if aspect >= 1 else (max(int(GRID * aspect), 20), GRID)
    grid_lat, grid_lon = np.meshgrid(np.linspace(north, south, ny), np.linspace(west, east, nx), indexing="ij")
    try:
        height = dem.height_m(grid_lat.ravel(), grid_lon.ravel()).reshape(ny, nx)
    except MissingTileError:
        return None
    if not np.isfinite(height).any():
        return None
    height = np.where(np.isfinite(height), height, np.nanmean(height))
    dx = (east - west) / (nx - 1) * M_PER_DEG * np.cos(np.radians(0.5 * (south + north)))
    dy = (north - south) / (ny - 1) * M_PER_DEG
    shade = LightSource(azdeg=315, altdeg=45).hillshade(height, vert_exag=2.0, dx=dx, dy=dy)
    return shade, (west, east, south, north)


def _gated(distance: np.ndarray, grid: pd.DataFrame | None) -> np.ndarray:
    """Per step between consecutive positions, whether the smoother gated the map out anywhere on
    it (the gradient grid, over distance): a tunnel without positions is one long gated step."""
    if grid is None or "map_gated" not in grid or "distance_m" not in grid:
        return np.zeros(max(len(distance) - 1, 0), bool)
    order = np.argsort(grid["distance_m"].to_numpy(float))
    bins = grid["distance_m"].to_numpy(float)[order]
    count = np.concatenate([[0], np.cumsum(grid["map_gated"].to_numpy(float)[order] > 0)])
    return count[np.searchsorted(bins, distance[1:], side="right")] - count[np.searchsorted(bins, distance[:-1])] > 0


def route_figure(lat, lon, gradient, gated_step, shade=None):
    """The route coloured by gradient over the hillshade; gated stretches outlined in black, also
    across a gap in the positions (a tunnel is both); other gaps dotted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    segments, joined = _segments(lat, lon)
    figure, ax = plt.subplots(figsize=(9, 7), layout="constrained")
    if shade is not None:
        ax.imshow(shade[0], extent=shade[1], cmap="gray", vmin=0, vmax=1, alpha=0.55, interpolation="bilinear")
    if gated_step.any():
        ax.add_collection(LineCollection(segments[gated_step], colors="black", linewidths=6,
                                         label="map gated out (bridge, tunnel, cutting)"))
    finite = np.isfinite(gradient)
    limit = float(np.nanpercentile(np.abs(gradient[finite]), 99)) if finite.any() else 1.0
    lines = LineCollection(segments[joined], cmap="RdYlBu_r", linewidths=2.6)
    lines.set_array(0.5 * (gradient[:-1] + gradient[1:])[joined])
    lines.set_clim(-max(limit, 0.5), max(limit, 0.5))
    ax.add_collection(lines)
    figure.colorbar(lines, ax=ax, label="gradient [%]", shrink=0.8)
    across = ~joined & ~gated_step
    if across.any():
        ax.add_collection(LineCollection(segments[across], colors="#57606a", linewidths=1, linestyles=":",
                                         label="no positions in between"))
    ax.plot(lon[0], lat[0], "o", color="#1a7f37", ms=8, label="start")
    ax.plot(lon[-1], lat[-1], "s", color="#cf222e", ms=8, label="end")
    ax.set_aspect(1 / np.cos(np.radians(np.mean(lat))))
    ax.autoscale_view()
    if shade is not None:
        ax.set_xlim(shade[1][0], shade[1][1])
        ax.set_ylim(shade[1][2], shade[1][3])
    ax.set_xlabel("longitude [°]")
    ax.set_ylabel("latitude [°]")
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.08), ncol=3, fontsize=8, frameon=False)
    return figure


def route_section(signals: pd.DataFrame, summary: dict, out_dir: Path, dem_dir=None, private: bool = False) -> Section:
    """The chapter: the map, or why there is none."""
    section = Section(TITLE)
    if private:
        section.notes.append("No map: the run is private (--private), and a map shows where the truck went.")
        return section
    track = _track(signals)
    if track is None:
        section.notes.append("No map: the log holds no GPS positions.")
        return section
    lat, lon, gradient, distance = track
    grid_file = Path(out_dir) / "gradient.csv"
    grid = pd.read_csv(grid_file, usecols=lambda c: c in ("distance_m", "map_gated")) if grid_file.is_file() else None
    gated = _gated(distance, grid)
    shade = None
    if dem_dir is not None:
        from ..dem import open_dem

        shade = hillshade(open_dem(dem_dir), lat, lon)
    figure = route_figure(lat, lon, gradient, gated, shade)
    _, joined = _segments(lat, lon)
    section.kpis = [("positions", f"{len(lat):,}"), ("gaps in the track", str(int((~joined).sum())))]
    if gated.any():
        section.kpis.append(("map gated out", f"{np.diff(distance)[gated].sum() / 1000:.2f} km"))
    background = ("a hillshade of the run's elevation model" if shade is not None
                  else "no background (no elevation model given, or none covers the route)")
    section.figures.append((figure, f"The route coloured by the estimated gradient over {background}; black "
                                    f"underneath: where the smoother gated the elevation model out. Positions more "
                                    f"than {GAP_M:.0f} m apart (a privacy zone, a GPS outage) are not joined."))
    return section
