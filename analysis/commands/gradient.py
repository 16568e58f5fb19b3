"""``analyze gradient INPUT… [--dem DIR] [--out DIR]``: road height and gradient of each source and
fused, on the distance grid; a figure like the paper's Fig. 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import checks
from ..errors import UserError
from .arguments import add_dem, add_inputs, add_out, refuse_cycles


def add_arguments(parser) -> None:
    add_inputs(parser)
    add_dem(parser, "else barometer only")
    add_out(parser, Path("gradient-out"))
    parser.add_argument("--spacing", type=float, default=10.0, help="distance grid spacing [m] (default 10)")
    parser.add_argument("--no-figure", action="store_true", help="skip the figure")
    parser.add_argument("--gradient-method", choices=("smoother", "paper"), default="smoother",
                        help="gradient_pct from the Kalman smoother (default) or the paper's fusion (8)")


def run(args) -> int:
    refuse_cycles(args.inputs, "gradient")
    from ..gradient import GradientSettings
    from ..gradient.stage import GradientOptions
    from ..outputs import OutputOptions
    from ..pipeline import Options, RunContext, run as run_pipeline

    checks.positive(args.spacing, "--spacing", "m")
    options = Options(gradient=GradientOptions(GradientSettings(spacing_m=args.spacing, gradient_method=args.gradient_method),
                                               barometer_off_map=True),
                      output=OutputOptions(figures=not args.no_figure))
    ctx = RunContext(inputs=list(args.inputs), out_dir=args.out, dem_dir=args.dem, options=options)
    ctx = run_pipeline(ctx, until="gradient")
    if ctx.results.gradient is None:
        raise UserError(ctx.skipped.get("gradient", "no gradient estimated"))
    grid = ctx.results.gradient.grid
    gradient = grid["gradient_pct"].to_numpy()
    print(f"{grid['distance_m'].iloc[-1] / 1000:.2f} km on a {args.spacing:g} m grid; gradient "
          f"{np.nanmin(gradient):+.2f} .. {np.nanmax(gradient):+.2f} %, mean map weight {grid['weight_map'].mean():.2f}")
    for name in ctx.summary["gradient"]["files"]:
        print(f"wrote {args.out / name}")
    return 0
