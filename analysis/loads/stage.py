"""The loads stage: wheel load collectives of the measured drive and of the selected cycle (in
memory, `LoadsResult`); `write_loads` is its part of the output step (CSVs and figures),
`loads_chapter` its report chapter."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import UserError
from ..kinematics import acceleration_mps2
from ..signals import CYCLE_SUFFIXES, missing_for, read_signals
from ..stage import Stage
from ..stop_mass import with_mass_at_stops
from . import NEEDED, collectives_of
from .bins import apply_overrides, default_edges
from .chapter import TITLE, loads_chapter
from .output import FILES, write_csvs, write_figures
from .summary import Collectives, compare, summary


@dataclass(frozen=True)
class LoadsOptions:
    """Options of the loads stage."""

    common_rate: bool = True
    """Average every drive onto the coarsest drive's sample interval before counting."""
    generated_file: Path | None = None
    """A generated cycle table (CSV/Parquet with the `NEEDED` columns) to compare with, instead of
    the cycle stage's (``analyze loads --cycle``)."""
    bin_overrides: tuple = ()
    """Axes replacing the vehicle class's bins (`loads.bins.read_overrides` of a TOML file)."""


@dataclass
class LoadsResult:
    collectives: dict[str, Collectives]
    """Per drive ("measured", "generated"): time at level, residence, rainflow, damage-equivalent torques."""
    comparison: pd.DataFrame | None
    """Measured against generated, one row per criterion (both drives only)."""

    def summary(self) -> dict:
        """Per drive its collectives' figures and, with both drives, the relative deviations."""
        result = {name: summary(c) for name, c in self.collectives.items()}
        if self.comparison is not None:
            result["comparison"] = {row.criterion: (float(row.relative_deviation)
                                                    if np.isfinite(row.relative_deviation) else None)
                                    for row in self.comparison.itertuples()}
        return result


def loads_stage(ctx) -> LoadsResult | None:
    """Load collectives of the measured drive and, if there is one, the selected cycle.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``signals`` (time_s [s], speed_mps [m/s], accel_mps2 [m/s²], gradient_pct [%],
        mass_kg [kg]), ``results.cycle``, ``vehicle`` and ``options.loads`` (`LoadsOptions`).

    References
    ----------
    Wheel force, torque, speed and power from equations (1)-(4); rainflow counting per ASTM E1049.
    """
    options: LoadsOptions = ctx.options.loads
    missing = missing_for(ctx.signals, NEEDED) if ctx.signals is not None else NEEDED
    if missing:
        ctx.skip("loads", f"the signals lack {', '.join(missing)}")
        return None
    if ctx.vehicle is None:
        ctx.skip("loads", "no vehicle file")
        return None
    drives = {"measured": with_mass_at_stops(ctx.signals)}
    if options.generated_file is not None:
        generated = read_signals(options.generated_file)
        if is_cycle_path(options.generated_file):
            generated = standard_cycle(generated, ctx)
        lacking = missing_for(generated, NEEDED)
        if lacking:
            raise UserError(f"{options.generated_file}: the generated cycle lacks {', '.join(lacking)}; "
                            f"estimate them first (the gradient and mass stages)")
        drives["generated"] = generated
    elif ctx.results.cycle is not None:
        drives["generated"] = ctx.results.cycle.frame
    edges = apply_overrides(default_edges(ctx.vehicle), options.bin_overrides)
    collectives = collectives_of(drives, ctx.vehicle, options.common_rate, edges)
    comparison = (compare(collectives["measured"], collectives["generated"])
                  if {"measured", "generated"} <= set(collectives) else None)
    result = LoadsResult(collectives, comparison)
    for name, c in collectives.items():
        s = summary(c)
        ctx.say(f"loads: {name}: {s['rainflow_cycles']:.0f} rainflow cycles, damage-equivalent torque range "
                f"(k=5) {s['damage_equivalent_torque_range_nm']['5']:.0f} Nm")
    return result


def is_cycle_path(path: Path) -> bool:
    return Path(path).suffix.lower() in CYCLE_SUFFIXES


def standard_cycle(cycle: pd.DataFrame, ctx) -> pd.DataFrame:
    """A VECTO cycle's time trace with what the loads need: the acceleration from its speed and,
    since a VECTO cycle carries no mass, the measured drive's median mass **[choice: the cycle is
    driven by the truck it is compared with]**, said in the run's messages."""
    cycle = cycle.copy()
    cycle["accel_mps2"] = acceleration_mps2(cycle["time_s"].to_numpy(float), cycle["speed_mps"].to_numpy(float))
    mass = float(np.nanmedian(ctx.signals["mass_kg"].to_numpy(float)))
    cycle["mass_kg"] = mass
    ctx.say(f"loads: the VECTO cycle is driven at the measured drive's median mass, {mass:.0f} kg")
    return cycle


def write_loads(result: LoadsResult, directory: Path, figures: bool = True) -> list[str]:
    """Each drive's collectives as CSV files, ``comparison.csv`` and, with ``figures``, the figures;
    returns the names."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for c in result.collectives.values():
        written += write_csvs(c, directory)
    if result.comparison is not None:
        result.comparison.to_csv(directory / "comparison.csv", index=False)
        written.append(directory / "comparison.csv")
    if figures:
        written += write_figures(list(result.collectives.values()), result.comparison, directory)
    return [path.name for path in written]


STAGE = Stage("loads", LoadsOptions, loads_stage, write=write_loads, files=FILES, folder="loads",
              chapter=loads_chapter, title=TITLE, reads_vehicle=True)
