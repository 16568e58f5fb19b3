"""Paper Fig. 2 for a gradient result: heights of each source, the sources' weights, gradients over distance."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def draw_sources(grid, path: Path) -> Path:
    """Paper Fig. 2 extended: height of each source; the smoother's source weights along the route
    with the stretches where the map was gated out (and the paper's w_map); the gradients."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    km = grid["distance_m"].to_numpy() / 1000
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(12, 8), height_ratios=[3, 1.5, 2])
    for column, label in (("height_map_m", "map-matching (DEM)"), ("height_baro_m", "barometric"),
                          ("height_paper_m", "paper fusion (8)"), ("height_smooth_m", "smoother")):
        if column in grid:
            axes[0].plot(km, grid[column], label=label, lw=1.6 if column == "height_smooth_m" else 1)
    axes[0].set_ylabel("height [m]")
    _legend_outside(axes[0])
    for name in ("baro", "map", "imu", "gps"):
        column = f"weight_smooth_{name}"
        if column in grid and np.any(grid[column] > 0):
            axes[1].plot(km, grid[column], label=f"smoother: {name}")
    axes[1].plot(km, grid["weight_map"], ":", color="grey", label="paper w_map")
    if "map_gated" in grid and grid["map_gated"].any():
        axes[1].fill_between(km, 0, 1, where=grid["map_gated"].to_numpy(bool), color="red", alpha=0.15,
                             label="map gated out")
    axes[1].set_ylabel("weight [-]")
    axes[1].set_ylim(-0.05, 1.05)
    _legend_outside(axes[1])
    for column, label, style in (("gradient_imu_pct", "IMU (raw)", ":"), ("gradient_map_pct", "map", "-"),
                                 ("gradient_baro_pct", "barometric", "-"), ("gradient_paper_pct", "paper (8)", "-"),
                                 ("gradient_smooth_pct", "smoother", "-")):
        if column in grid:
            axes[2].plot(km, grid[column], style, label=label, lw=1.6 if column == "gradient_smooth_pct" else 0.8)
    axes[2].set_ylabel("gradient [%]")
    axes[2].set_xlabel("distance [km]")
    _legend_outside(axes[2])
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _legend_outside(ax) -> None:
    """The legend right of the panel, where it covers no curve."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
