"""Figure like the paper's Fig. 7: speed, gradient and mass over time of the generated cycle, and
measured against generated distributions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd


def plot_cycle(cycle: pd.DataFrame, measured_1hz: pd.DataFrame, path: str | Path, title: str = "") -> Path:
    """Write the figure as PNG (matplotlib, no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = (("speed_mps", "speed [km/h]", 3.6), ("gradient_pct", "gradient [%]", 1.0),
            ("mass_kg", "mass [t]", 1e-3))
    fig, axes = plt.subplots(3, 2, figsize=(11, 7.5), gridspec_kw={"width_ratios": [3, 1]})
    for (column, label, scale), (left, right) in zip(rows, axes):
        left.plot(cycle["time_s"], cycle[column] * scale, lw=0.8, color="C1")
        left.set_ylabel(label)
        left.grid(alpha=0.3)
        measured = measured_1hz[column].to_numpy(float) * scale
        generated = cycle[column].to_numpy(float) * scale
        low, high = np.nanmin([measured.min(), generated.min()]), np.nanmax([measured.max(), generated.max()])
        bins = np.linspace(low, high if high > low else low + 1, 31)
        right.hist(measured, bins=bins, density=True, alpha=0.5, color="C0", label="measured",
                   orientation="horizontal")
        right.hist(generated, bins=bins, density=True, histtype="step", color="C1", label="generated",
                   orientation="horizontal")
        right.set_xlabel("density")
    axes[0, 1].legend(fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_scores(selections, path: str | Path) -> Path:
    """Distribution of the score S (15) over the Monte Carlo candidates, with the chosen cycle(s)
    marked; for refined cycles also where each refinement started."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first = selections[0]
    scores = np.asarray(first.all_scores, float)
    fig, ax = plt.subplots(figsize=(8, 3.6))
    finite = scores[np.isfinite(scores)]
    high = np.quantile(finite, 0.995) if finite.size else 1.0
    bins = np.linspace(0.0, max(high, max(s.criteria.score for s in selections)) * 1.05 + 1e-9, 80)
    ax.hist(np.clip(finite, None, bins[-1]), bins=bins, color="C0", alpha=0.6,
            label=f"{len(scores):,} Monte Carlo candidates")
    ax.axvline(1.0, color="0.5", lw=0.8, ls=":")
    for i, s in enumerate(selections):
        label = "chosen" if i == 0 else None
        if s.method != "paper":
            ax.annotate("", xy=(s.criteria.score, 0.5), xytext=(s.start_score, 0.5), xycoords=("data", "axes fraction"),
                        arrowprops={"arrowstyle": "->", "color": "C1", "lw": 0.8})
            label = "refined cycle(s), arrow from its start" if i == 0 else None
        if i == 1:
            label = "other cycles of the set"
        ax.axvline(s.criteria.score, color="C1" if i == 0 else "C2", lw=1.2, label=label)
    ax.set_yscale("log")
    ax.set_xlabel("score S (15) of the paper's criteria, lower is better")
    ax.set_ylabel("candidates")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
