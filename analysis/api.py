"""The analysis as Python calls, for notebooks and scripts (``docs/python-api.md``).

``run`` is ``analyze run`` returning the signals table (pandas), the stages' typed results and the
summary (dict) besides writing the files; the single stages are re-exported from ``analysis``
(``analysis.read_logs``, ``analysis.estimate_mass`` …) and return DataFrames and NumPy arrays.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from .pipeline import Results, RunContext, run as run_pipeline
from .errors import UserError
from .vehicle import Vehicle, load_vehicle


@dataclass
class RunResult:
    """What ``analyze run`` produces, in memory: the signals table, the summary and where files went."""

    signals: pd.DataFrame
    summary: dict
    out_dir: Path | None
    """Where the files went (None: no ``out`` was given, none were kept)."""
    results: Results = field(default_factory=Results)
    """Each stage's typed result (``results.mass``, ``results.cycle``, ``results.simulation`` …)."""

    @property
    def cycle(self) -> pd.DataFrame | None:
        """The chosen representative cycle (1 Hz: time_s, speed_mps, accel_mps2, gradient_pct,
        mass_kg, distance_m), or None when the cycle stage did not run."""
        return self.results.cycle.frame if self.results.cycle is not None else None

    @property
    def mass_segments(self) -> pd.DataFrame:
        """One row per segment between stops: LS/RLS/LM masses, uncertainty, CAN estimate, status."""
        return pd.DataFrame(self.results.mass.segments if self.results.mass is not None else [])


def _paths(value, what: str) -> list[Path]:
    """A path or a list of paths (str or `os.PathLike`); anything else is one `UserError`."""
    items = [value] if isinstance(value, (str, os.PathLike)) else value
    if isinstance(items, (bytes, dict)) or not hasattr(items, "__iter__"):
        raise UserError(f"{what} must be a path or a list of paths (str or Path), got {type(value).__name__}")
    items = list(items)
    bad = [item for item in items if not isinstance(item, (str, os.PathLike))]
    if bad or not items:
        raise UserError(f"{what} must be a path or a list of paths (str or Path), got "
                        + (f"a {type(bad[0]).__name__}" if bad else "none"))
    return [Path(item) for item in items]


def run(inputs, vehicle: str | Path | Vehicle, dem: str | Path | None = None, out: str | Path | None = None,
        until: str | None = None, cache: bool = True, quiet: bool = True, **options) -> RunResult:
    """Run the stages on logs, directories of logs or signals tables (``analyze run`` in memory).

    Parameters
    ----------
    inputs : str, Path or list of them
        MCAP logs, directories of logs, other loggers' CAN logs, or signals tables (CSV/Parquet).
    vehicle : str, Path or Vehicle
        A vehicle file (TOML), a shipped example name (``"rigid-18t"``) or a `Vehicle`.
    dem : str or Path, optional
        Directory of SRTM ``.hgt`` tiles or GeoTIFFs; without it the gradient is barometric only.
    out : str or Path, optional
        Output directory; without it the files go to a temporary folder that is removed before
        this returns (it holds positions and times), the results stay in memory and
        ``out_dir`` is None.
    until : str, optional
        Last stage to run (``"mass"``, ``"cycle"`` …); default every stage and the report.
    cache : bool
        Reuse unchanged stages' results from ``out/.cache`` (keyed by content).
    quiet : bool
        Say nothing (else the stages' messages are printed).
    **options
        Per-stage keyword tables or option objects, e.g. ``cycle={"n_candidates": 2000, "seed": 1}``,
        ``ingest={"rate_hz": 5}``, ``simulation={"payload_kg": 6000}`` (`pipeline.Options`).

    Returns
    -------
    RunResult
        The signals table [SI units], the summary, the stages' typed results and the output directory.

    References
    ----------
    Gradient: paper equations (5)-(8); mass: (9)-(14); cycle selection: (15).
    """
    inputs = _paths(inputs, "inputs")
    if not isinstance(vehicle, (str, os.PathLike, Vehicle)):
        raise UserError(f"vehicle must be a vehicle file, a shipped name or a Vehicle, got {type(vehicle).__name__}")
    if dem is not None and not isinstance(dem, (str, os.PathLike)):
        raise UserError(f"dem must be a folder (str or Path), got {type(dem).__name__}")
    if out is not None and not isinstance(out, (str, os.PathLike)):
        raise UserError(f"out must be a folder (str or Path), got {type(out).__name__}")
    with tempfile.TemporaryDirectory(prefix="haulprofile-") as scratch:
        out_dir = Path(out) if out is not None else Path(scratch)
        ctx = RunContext(inputs=inputs, out_dir=out_dir,
                         vehicle=vehicle if isinstance(vehicle, Vehicle) else load_vehicle(vehicle),
                         dem_dir=Path(dem) if dem is not None else None, options=options,
                         say=(lambda _m: None) if quiet else print)
        run_pipeline(ctx, until=until, cache=cache and out is not None)
    return RunResult(ctx.signals, ctx.summary, out_dir if out is not None else None, ctx.results)
