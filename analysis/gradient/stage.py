"""The gradient stage: `estimate_gradient` on the signals table, its columns added in memory;
`write_gradient` is its part of the output step (``gradient.csv``, ``gradient.png``),
`gradient_chapter` its report chapter."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..dem import MissingTileError, open_dem
from ..dem.plausible import ImplausibleDemError
from ..errors import UserError
from ..stage import Stage
from .chapter import TITLE, gradient_chapter
from .estimate import GradientResult, GradientSettings
from .figure import draw_sources
from .force_balance import estimate_gradient_for_log
from .sensor_sets import describe, sensor_set


@dataclass(frozen=True)
class GradientOptions:
    """Options of the gradient stage."""

    settings: GradientSettings = field(default_factory=GradientSettings)
    """Grid spacing [m], smoothing lengths and ``gradient_method`` ("smoother", the default, or
    the paper's fusion "paper") of the estimate."""
    barometer_off_map: bool = False
    """Where the route leaves the DEM, say so and fall back to the barometer alone (``analyze
    gradient``); otherwise that is an error naming the missing tile (``analyze run``)."""
    keep_existing: bool = False
    """Keep a ``gradient_pct`` column the input already has instead of estimating it again."""
    flat_road: bool = False
    """Take the road as flat (gradient 0 %) instead of estimating it: for a log without barometer,
    DEM or GPS height (a CAN-only recording), said as such in the summary and the report."""


@dataclass
class FlatRoad:
    """The gradient stage's result when ``flat_road`` was asked for: no estimate, 0 % everywhere."""

    def summary(self) -> dict:
        return {"method": "flat_road", "sources": [], "gradient_pct": {"mean": 0.0, "min": 0.0, "max": 0.0},
                "height_gain_m": 0.0, "notes": [FLAT_ROAD_NOTE]}


FLAT_ROAD_NOTE = ("the road was taken as flat (gradient 0 %, flat_road), not estimated: climbing and descending "
                  "loads and energy are missing from every result after it")


def gradient_stage(ctx) -> GradientResult | FlatRoad | None:
    """Add ``height_m``, ``gradient_pct`` (the smoother's or the paper's fusion (8), by
    ``options.settings.gradient_method``), both methods' and each source's columns to ``ctx.signals``.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``signals`` (time_s [s], speed_mps [m/s]; latitude_deg/longitude_deg [deg] with a DEM,
        pressure_pa [Pa] for the barometer), ``dem_dir`` and ``options.gradient`` (`GradientOptions`).

    References
    ----------
    Paper §2.2.1, equations (5)-(8).
    """
    options: GradientOptions = ctx.options.gradient
    frame = ctx.signals
    if options.flat_road:
        frame["gradient_pct"] = 0.0
        ctx.say(f"gradient: {FLAT_ROAD_NOTE}")
        return FlatRoad()
    if options.keep_existing and "gradient_pct" in frame.columns and frame["gradient_pct"].notna().any():
        return None
    ctx.say(f"gradient: {describe(frame)}")
    if ctx.dem_dir is None:
        ctx.say("gradient: no DEM given: barometric height only (no map-matching)")
    dem = open_dem(ctx.dem_dir) if ctx.dem_dir is not None else None
    try:
        try:
            result = estimate_gradient_for_log(frame, dem, options.settings, ctx.vehicle)
        except (MissingTileError, ImplausibleDemError) as exc:
            if not options.barometer_off_map:
                raise type(exc)(f"{exc}; or run without dem_dir for barometric height only") from None
            ctx.say(f"gradient: {exc}; using the barometer alone")
            result = estimate_gradient_for_log(frame, None, options.settings, ctx.vehicle)
    except (MissingTileError, ImplausibleDemError):
        raise
    except UserError as exc:
        ctx.skip("gradient", str(exc))
        return None
    for note in result.notes:
        ctx.say(f"gradient: {note}")
    for name, values in result.samples.items():
        frame[name] = values
    result.settings = options.settings
    result.sensor_set = sensor_set(frame)
    return result


def write_gradient(result: GradientResult | FlatRoad, directory: Path, figures: bool = True) -> list[str]:
    """``gradient.csv`` (the distance grid) and, with ``figures``, ``gradient.png``; returns the names
    (none for a flat road)."""
    if isinstance(result, FlatRoad):
        return []
    result.grid.to_csv(directory / "gradient.csv", index=False)
    files = ["gradient.csv"]
    if figures:
        files.append(draw_sources(result.grid, directory / "gradient.png").name)
    return files


STAGE = Stage("gradient", GradientOptions, gradient_stage, write=write_gradient, files=("gradient.csv", "gradient.png"),
              chapter=gradient_chapter, title=TITLE, reads_dem=True, reads_vehicle=True)
