"""The analysis as Python calls, for notebooks and scripts (``docs/python-api.md``).

``run`` is ``analyze run`` returning the signals table (pandas) and the summary (dict) instead of
only writing files; the single stages are re-exported from ``analysis`` (``analysis.read_logs``,
``analysis.estimate_mass`` …) and return DataFrames and NumPy arrays.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from .pipeline import RunContext, run as run_pipeline
from .vehicle import Vehicle, load_vehicle


@dataclass
class RunResult:
    """What ``analyze run`` produces, in memory: the signals table, the summary and where files went."""

    signals: pd.DataFrame
    summary: dict
    out_dir: Path

    @property
    def cycle(self) -> pd.DataFrame | None:
        """The chosen representative cycle (1 Hz: time_s, speed_mps, accel_mps2, gradient_pct, mass_kg)."""
        path = self.out_dir / "cycle.parquet"
        return pd.read_parquet(path) if path.is_file() else None

    @property
    def mass_segments(self) -> pd.DataFrame:
        """One row per segment between stops: LS/RLS/LM masses, uncertainty, CAN estimate, status."""
        return pd.DataFrame(self.summary.get("mass", {}).get("segments", []))


def run(inputs, vehicle: str | Path | Vehicle, dem: str | Path | None = None, out: str | Path | None = None,
        until: str | None = None, cache: bool = True, quiet: bool = True, **options) -> RunResult:
    """Run the stages on logs, directories of logs or signals tables.

    ``vehicle`` is a vehicle file, a shipped example name or a `Vehicle`; ``out`` defaults to a new
    temporary directory; ``until`` stops after a stage (e.g. ``"mass"``); ``options`` are per-stage
    tables as on the command line's pipeline, e.g. ``cycle={"n_candidates": 2000, "seed": 1}``.
    """
    inputs = [Path(p) for p in ([inputs] if isinstance(inputs, (str, Path)) else inputs)]
    out_dir = Path(out) if out is not None else Path(tempfile.mkdtemp(prefix="haulprofile-"))
    ctx = RunContext(inputs=inputs, out_dir=out_dir,
                     vehicle=vehicle if isinstance(vehicle, Vehicle) else load_vehicle(vehicle),
                     dem_dir=Path(dem) if dem is not None else None, options=options,
                     say=(lambda _m: None) if quiet else print)
    run_pipeline(ctx, until=until, cache=cache)
    return RunResult(ctx.signals, ctx.summary, out_dir)
