"""``analyze gradient INPUT… [--dem DIR] [--out DIR]``: road height and gradient of each source and
fused, on the distance grid; a figure like the paper's Fig. 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import checks
from ..errors import UserError
from ..pipeline import RunContext, available_stages, load_inputs


def add_arguments(parser) -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help="MCAP logs, directories of logs, or signals tables")
    parser.add_argument("--dem", type=Path, help="directory of SRTM .hgt tiles or GeoTIFFs (else barometer only)")
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path, default=Path("gradient-out"),
                        help="output directory")
    parser.add_argument("--spacing", type=float, default=10.0, help="distance grid spacing [m] (default 10)")
    parser.add_argument("--no-figure", action="store_true", help="skip the figure")


def signals_for(inputs, say, out_dir: Path, vehicle=None, dem_dir=None, options=None) -> RunContext:
    """Signals table of the inputs after ingest and kinematics (what the gradient and mass stages read)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    ctx = RunContext(inputs=list(inputs), out_dir=out_dir, vehicle=vehicle, dem_dir=dem_dir,
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
    from ..gradient.figure import draw_sources

    checks.output_dir(args.out, args.inputs)
    checks.positive(args.spacing, "--spacing", "m")
    ctx = signals_for(args.inputs, print, args.out, dem_dir=args.dem)
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
