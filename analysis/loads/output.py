"""CSV files and figures of the load collectives."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from ..units import unit_of  # noqa: E402
from .collectives import QUANTITIES  # noqa: E402
from .summary import Collectives  # noqa: E402


DRIVES = ("measured", "generated")
COLLECTIVES = (*(f"time_at_level_{quantity}" for quantity in QUANTITIES), "residence_speed_torque_s",
               "rainflow_range_mean_counts", "level_crossings_torque", "damage_equivalent_torque")
FIGURES = ("time_at_level.png", "matrices.png", "crossings_damage.png")
FILES = (*(f"{drive}_{what}.csv" for drive in DRIVES for what in COLLECTIVES), "comparison.csv", *FIGURES)
"""Every file the loads stage may write into its folder."""


def _bin_labels(edges, unit: str) -> list[str]:
    return [f"{a:.6g}..{b:.6g} {unit}" for a, b in zip(edges[:-1], edges[1:])]


def _matrix(values, row_axis: str, column_axis: str, row_edges, column_edges) -> pd.DataFrame:
    """A matrix with its bins as row and column labels (``0..25 rpm``); the index header names both
    axes (``wheel_speed_rpm \\ wheel_torque_nm``), units by their names' suffix."""
    return pd.DataFrame(values, index=pd.Index(_bin_labels(row_edges, unit_of(row_axis)),
                                               name=f"{row_axis} \\ {column_axis}"),
                        columns=_bin_labels(column_edges, unit_of(column_axis)))


def write_csvs(c: Collectives, out_dir: Path) -> list[Path]:
    """One drive's collectives as CSV files named ``<drive>_<collective>.csv``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    prefix = c.name.replace(" ", "_")
    written = []

    def save(frame: pd.DataFrame, what: str, index=False):
        path = out_dir / f"{prefix}_{what}.csv"
        frame.to_csv(path, index=index)
        written.append(path)

    for quantity in QUANTITIES:
        edges = c.edges[quantity]
        save(pd.DataFrame({f"{quantity}_low": edges[:-1], f"{quantity}_high": edges[1:],
                           "time_s": c.time_at_level[quantity]}), f"time_at_level_{quantity}")
    save(_matrix(c.residence_s, "wheel_speed_rpm", "wheel_torque_nm", c.edges["residence_speed_rpm"],
                 c.edges["residence_torque_nm"]), "residence_speed_torque_s", index=True)
    save(_matrix(c.rainflow_counts, "range_nm", "mean_nm", c.edges["rainflow_range_nm"], c.edges["rainflow_mean_nm"]),
         "rainflow_range_mean_counts", index=True)
    save(pd.DataFrame({"wheel_torque_nm": c.crossing_levels_nm, "upward_crossings": c.crossings}),
         "level_crossings_torque")
    save(pd.DataFrame({"woehler_exponent": list(c.damage_equivalent_torque_nm),
                       "damage_equivalent_torque_range_nm": list(c.damage_equivalent_torque_nm.values()),
                       "equivalent_cycles": c.duration_s}), "damage_equivalent_torque")
    return written


FIGURE_UNITS = {"wheel_force_n": ("wheel force [kN]", 1e-3), "wheel_torque_nm": ("wheel torque [kNm]", 1e-3),
                "wheel_speed_rpm": ("wheel speed [rpm]", 1.0), "wheel_power_w": ("wheel power [kW]", 1e-3)}
"""Axis label and scale of each quantity in the figures: kN, kNm and kW keep tick labels short."""
KNM = 1e-3


def write_figures(drives: list[Collectives], comparison: pd.DataFrame | None, out_dir: Path) -> list[Path]:
    """Histograms, residence and rainflow matrices, level crossings and damage-equivalent torques."""
    written = []
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    for ax, quantity in zip(axes.ravel(), QUANTITIES):
        label, scale = FIGURE_UNITS[quantity]
        for c in drives:
            edges = c.edges[quantity]
            share = c.time_at_level[quantity] / max(c.duration_s, 1e-12) * 100
            ax.stairs(share, edges * scale, label=c.name)
        ax.set_xlabel(label)
        ax.set_ylabel("time share [%]")
    axes[0, 0].legend()
    fig.suptitle("time at level at the wheel")
    fig.tight_layout()
    written.append(_save(fig, out_dir / "time_at_level.png"))

    fig, axes = plt.subplots(2, len(drives), figsize=(6 * len(drives), 9), squeeze=False)
    for col, c in enumerate(drives):
        hours = np.where(c.residence_s > 0, c.residence_s / 3600, np.nan)
        mesh = axes[0, col].pcolormesh(c.edges["residence_speed_rpm"], c.edges["residence_torque_nm"] * KNM, hours.T,
                                       norm=LogNorm())
        fig.colorbar(mesh, ax=axes[0, col], label="residence [h]")
        axes[0, col].set(xlabel="wheel speed [rpm]", ylabel="wheel torque [kNm]", title=f"{c.name}: speed x torque")
        counts = np.where(c.rainflow_counts > 0, c.rainflow_counts, np.nan)
        mesh = axes[1, col].pcolormesh(c.edges["rainflow_range_nm"] * KNM, c.edges["rainflow_mean_nm"] * KNM, counts.T,
                                       norm=LogNorm())
        fig.colorbar(mesh, ax=axes[1, col], label="cycles")
        axes[1, col].set(xlabel="torque range [kNm]", ylabel="torque mean [kNm]", title=f"{c.name}: rainflow")
    fig.tight_layout()
    written.append(_save(fig, out_dir / "matrices.png"))

    fig, (ax_cross, ax_det) = plt.subplots(1, 2, figsize=(11, 4))
    for c in drives:
        per_hour = c.crossings / max(c.duration_s, 1e-12) * 3600
        ax_cross.semilogx(np.where(per_hour > 0, per_hour, np.nan), c.crossing_levels_nm * KNM, label=c.name)
        ax_det.plot(list(c.damage_equivalent_torque_nm), np.array(list(c.damage_equivalent_torque_nm.values())) * KNM,
                    "o-", label=c.name)
    ax_cross.set(xlabel="upward crossings per hour", ylabel="wheel torque [kNm]", title="level crossings")
    ax_det.set(xlabel="Wöhler exponent k", ylabel="damage-equivalent torque range [kNm]",
               title="1 cycle per second of operation")
    ax_det.legend()
    fig.tight_layout()
    written.append(_save(fig, out_dir / "crossings_damage.png"))
    return written


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
