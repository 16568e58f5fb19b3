"""Paper Fig. 6 for a mass result: each method's estimate over time, the CAN estimate, the real mass."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def draw_estimates(frame, result, path: Path, true_mass_kg: list[float] | None = None) -> Path:
    """Paper Fig. 6: the estimates of each method over time, the CAN estimate and the real mass."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    time_s = frame["time_s"].to_numpy()
    fig, ax = plt.subplots(figsize=(10, 5))
    for column, label in (("mass_rls_kg", "RLS"), ("mass_lm_kg", "Levenberg-Marquardt"), ("mass_ls_kg", "LS per segment")):
        ax.plot(time_s, result.columns[column] / 1000, label=label, lw=1.5 if column == "mass_ls_kg" else 0.8)
    if "reported_mass_kg" in frame:
        ax.plot(time_s, frame["reported_mass_kg"] / 1000, ".", ms=1, label="vehicle CAN estimate")
    if true_mass_kg and len(true_mass_kg) == len(result.segments) > 1:
        for k, (segment, mass) in enumerate(zip(result.segments, true_mass_kg)):
            ax.plot([segment["start_s"], segment["end_s"]], [mass / 1000] * 2, "k--", label="real mass" if k == 0 else None)
    elif true_mass_kg:
        ax.axhline(true_mass_kg[0] / 1000, color="k", ls="--", label="real mass")
    for segment in result.segments:
        if segment["uncertainty_kg"] not in (None, np.inf) and segment["mass_ls_kg"] is not None:
            ax.fill_between([segment["start_s"], segment["end_s"]],
                            (segment["mass_ls_kg"] - 2 * segment["uncertainty_kg"]) / 1000,
                            (segment["mass_ls_kg"] + 2 * segment["uncertainty_kg"]) / 1000, alpha=0.2, color="C2")
    ax.set_ylim(*_mass_limits_t(frame, result, true_mass_kg))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("mass [t]")
    ax.legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _mass_limits_t(frame, result, true_mass_kg) -> tuple[float, float]:
    """Mass axis [t] around what was estimated and reported, not the recursive estimators' start
    values (the first samples of RLS and LM sit wherever they were started)."""
    values = [m for m in (true_mass_kg or [])]
    for segment in result.segments:
        if segment.get("mass_ls_kg") is not None:
            spread = 2 * segment["uncertainty_kg"] if segment.get("uncertainty_kg") not in (None, np.inf) else 0.0
            values += [segment["mass_ls_kg"] - spread, segment["mass_ls_kg"] + spread]
    if "reported_mass_kg" in frame and frame["reported_mass_kg"].notna().any():
        values += list(np.nanpercentile(frame["reported_mass_kg"].to_numpy(float), [1, 99]))
    if not values:
        for column in ("mass_rls_kg", "mass_lm_kg"):
            series = np.asarray(result.columns[column], dtype=float)
            if np.isfinite(series).any():
                values += list(np.nanpercentile(series, [10, 99]))
    values = [v for v in values if np.isfinite(v)]
    if not values:
        return 0.0, 1.0
    low, high = min(values) / 1000, max(values) / 1000
    pad = max(0.08 * (high - low), 0.3)
    return low - pad, high + pad
