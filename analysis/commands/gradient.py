"""``analyze gradient INPUT… [--dem DIR] [--out DIR]``: road height and gradient of each source and
fused, on the distance grid; a figure like the paper's Fig. 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import UserError
from ..pipeline import RunContext, available_stages, load_inputs


def add_arguments(parser) -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help="MCAP logs, directories of logs, or signals tables")
    parser.add_argument("--dem", type=Path, help="directory of SRTM .hgt tiles or GeoTIFFs (else barometer only)")
    parser.add_argument("--out", type=Path, default=Path("gradient-out"), help="output directory")
    parser.add_argument("--spacing", type=float, default=10.0, help="distance grid spacing [m] (default 10)")
    parser.add_argument("--no-figure", action="store_true", help="skip the figure")


def signals_for(inputs, say, vehicle=None, dem_dir=None, options=None) -> RunContext:
    """Signals table of the inputs after ingest and kinematics (what the gradient and mass stages read)."""
    ctx = RunContext(inputs=list(inputs), out_dir=Path("."), vehicle=vehicle, dem_dir=dem_dir,
                     options=options or {}, say=say)
    load_inputs(ctx)
    stages = dict(available_stages())
    if ctx.signals is None:
        if "ingest" not in stages:
            raise UserError("these inputs are logs but the ingest stage is not installed; give a signals table")
        stages["ingest"](ctx)
    if "kinematics" in stages:
        stages["kinematics"](ctx)
    return ctx


def run(args) -> int:
    from ..gradient import GradientSettings, gradient_with_dem_fallback

    ctx = signals_for(args.inputs, print, dem_dir=args.dem)
    result = gradient_with_dem_fallback(ctx.signals, args.dem, GradientSettings(spacing_m=args.spacing), print)
    for note in result.notes:
        print(f"note: {note}")
    args.out.mkdir(parents=True, exist_ok=True)
    grid = result.grid
    grid.to_csv(args.out / "gradient.csv", index=False)
    gradient = grid["gradient_pct"].to_numpy()
    print(f"{grid['distance_m'].iloc[-1] / 1000:.2f} km on a {args.spacing:g} m grid; gradient "
          f"{np.nanmin(gradient):+.2f} .. {np.nanmax(gradient):+.2f} %, mean map weight {grid['weight_map'].mean():.2f}")
    print(f"wrote {args.out / 'gradient.csv'}")
    if not args.no_figure:
        print(f"wrote {draw_sources(grid, args.out / 'gradient.png')}")
    return 0


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
