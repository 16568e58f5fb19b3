"""Paper Fig. 2 for a gradient result: heights of each source, map weight, gradients over distance."""

from __future__ import annotations

from pathlib import Path


def draw_sources(grid, path: Path) -> Path:
    """Paper Fig. 2: height of each source, the map weight, and the fused gradient over distance."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    km = grid["distance_m"].to_numpy() / 1000
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(10, 8), height_ratios=[3, 1, 2])
    for column, label in (("height_map_m", "map-matching (DEM)"), ("height_baro_m", "barometric"),
                          ("height_m", "fused")):
        if column in grid:
            axes[0].plot(km, grid[column], label=label, lw=1.6 if column == "height_m" else 1)
    axes[0].set_ylabel("height [m]")
    axes[0].legend(loc="best")
    axes[1].plot(km, grid["weight_map"], label="w_map")
    axes[1].axhline(0.7, color="grey", ls="--", lw=0.8, label="w_baro")
    axes[1].set_ylabel("weight [-]")
    axes[1].set_ylim(-0.05, 1.05)
    axes[1].legend(loc="best")
    for column, label, style in (("gradient_imu_pct", "IMU (not fused)", ":"), ("gradient_map_pct", "map", "-"),
                                 ("gradient_baro_pct", "barometric", "-"), ("gradient_pct", "fused", "-")):
        if column in grid:
            axes[2].plot(km, grid[column], style, label=label, lw=1.6 if column == "gradient_pct" else 0.8)
    axes[2].set_ylabel("gradient [%]")
    axes[2].set_xlabel("distance [km]")
    axes[2].legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
