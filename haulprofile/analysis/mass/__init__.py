"""Vehicle mass (paper §2.2.2, equations (9)-(14)): the data filter, then least squares, recursive
least squares with forgetting and the damped Levenberg-Marquardt form, one mass per segment
between stops, each with an uncertainty.

Public: `estimate_mass(frame, vehicle, filter_settings, segment_settings) -> MassResult`; the
pipeline's stage, which adds ``mass_kg`` (and ``mass_ls_kg``, ``mass_rls_kg``, ``mass_lm_kg``), is
`analysis.mass.stage.mass_stage`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .regression import FilterSettings, Regression, build_regression
from .segments import SegmentSettings, estimate_segment, segment_bounds

__all__ = ["estimate_mass", "MassResult", "FilterSettings", "SegmentSettings"]


@dataclass
class MassResult:
    segments: list[dict]
    """Per segment: start_s, end_s, n_samples, mass_{ls,rls,lm}_kg, uncertainty_kg,
    reported_mass_kg, status, reason."""
    columns: dict[str, np.ndarray]
    """mass_kg (LS of 'ok' segments, else NaN), mass_ls_kg, mass_rls_kg, mass_lm_kg."""
    regression: Regression
    notes: list[str] = field(default_factory=list)


def estimate_mass(frame: pd.DataFrame, vehicle, filter_settings: FilterSettings = FilterSettings(),
                  segment_settings: SegmentSettings = SegmentSettings()) -> MassResult:
    """Per-segment masses [kg] of a signals table (see `MassResult`). UserError if columns are missing."""
    regression = build_regression(frame, vehicle, filter_settings)
    time_s = frame["time_s"].to_numpy(dtype=float)
    speed = frame["speed_mps"].to_numpy(dtype=float)
    reported = frame["reported_mass_kg"].to_numpy(dtype=float) if "reported_mass_kg" in frame else None
    max_mass = vehicle.curb_mass_kg + 2.0 * (vehicle.max_payload_kg or 3.0 * vehicle.curb_mass_kg)
    columns = {name: np.full(len(frame), np.nan) for name in ("mass_kg", "mass_ls_kg", "mass_rls_kg", "mass_lm_kg")}
    segments = []
    for start, end in segment_bounds(time_s, speed, segment_settings):
        part = slice(start, end)
        estimate = estimate_segment(regression.phi[part], regression.y[part], vehicle.curb_mass_kg, max_mass,
                                    segment_settings)
        if estimate["mass_ls_kg"] is not None:
            columns["mass_ls_kg"][part] = estimate["mass_ls_kg"]
            columns["mass_rls_kg"][part] = estimate.pop("rls_path")
            columns["mass_lm_kg"][part] = estimate.pop("lm_path")
            if estimate["status"] == "ok":
                columns["mass_kg"][part] = estimate["mass_ls_kg"]
        estimate.pop("rls_path", None)
        estimate.pop("lm_path", None)
        moving_report = None
        if reported is not None:
            values = reported[part][np.isfinite(reported[part]) & (speed[part] > 1.0)]
            moving_report = float(np.median(values)) if len(values) else None
        segments.append({"start_s": float(time_s[start]), "end_s": float(time_s[end - 1]), **estimate,
                         "reported_mass_kg": moving_report})
    notes = []
    if regression.usable.sum() == 0:
        worst = max(regression.rejected, key=regression.rejected.get)
        notes.append(f"no sample passes the data filter (most fail: {worst}, {regression.rejected[worst]} "
                     f"of {len(frame)}): no mass estimated")
    return MassResult(segments=segments, columns=columns, regression=regression, notes=notes)
