"""Files and figures of one simulation run: trace, summary, residence matrix, misses."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from .. import jsonable  # noqa: E402
from .model import SimulationResult  # noqa: E402

KMH_PER_MPS = 3.6


def residence_frame(result: SimulationResult) -> pd.DataFrame:
    """Machine operating-point residence [s]: rows speed bins [rpm], columns torque bins [Nm]."""
    speed, torque = result.residence_speed_edges_rpm, result.residence_torque_edges_nm
    return pd.DataFrame(result.residence_s,
                        index=pd.Index([f"{a:.0f}..{b:.0f}" for a, b in zip(speed[:-1], speed[1:])], name="speed_rpm"),
                        columns=[f"{a:.0f}..{b:.0f}" for a, b in zip(torque[:-1], torque[1:])])


FIGURES = ("speed_soc.png", "machine_residence.png")
FILES = ("trace.parquet", "summary.json", "residence_s.csv", "misses.csv", *FIGURES)
"""Every file the simulation writes into its folder."""


def write_outputs(result: SimulationResult, out_dir: Path, figures: bool = True) -> list[Path]:
    """Write ``trace.parquet``, ``summary.json``, ``residence_s.csv``, ``misses.csv`` and, with
    ``figures``, the figures."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = [out_dir / "trace.parquet", out_dir / "summary.json", out_dir / "residence_s.csv",
               out_dir / "misses.csv"]
    result.trace.to_parquet(written[0], index=False)
    written[1].write_text(jsonable.dumps(result.numbers, indent=2))
    residence_frame(result).to_csv(written[2])
    result.misses.to_csv(written[3], index=False)
    if figures:
        written += write_figures(result, out_dir)
    return written


def write_figures(result: SimulationResult, out_dir: Path) -> list[Path]:
    trace = result.trace
    x, x_label = ((trace["time_s"], "time [s]") if result.numbers["time_based"]
                  else (trace["distance_m"] / 1000.0, "distance [km]"))
    fig, (ax_speed, ax_soc) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    ax_speed.plot(x, trace["target_speed_mps"] * KMH_PER_MPS, lw=0.8, label="target")
    ax_speed.plot(x, trace["speed_mps"] * KMH_PER_MPS, lw=0.8, label="simulated")
    for _, miss in result.misses.iterrows():
        start = miss["start_time_s"] if result.numbers["time_based"] else miss["start_distance_m"] / 1000.0
        end = miss["end_time_s"] if result.numbers["time_based"] else miss["end_distance_m"] / 1000.0
        ax_speed.axvspan(start, end, color="red", alpha=0.3)
    ax_speed.set_ylabel("speed [km/h]")
    ax_speed.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=2, fontsize=8, frameon=False)
    ax_soc.plot(x, trace["soc"] * 100.0, lw=0.8)
    ax_soc.set_ylabel("state of charge [%]")
    ax_soc.set_xlabel(x_label)
    fig.suptitle(f"{result.numbers['cycle']}: {result.numbers['battery_kwh_per_km']:.3f} kWh/km at the battery")
    fig.tight_layout()
    speed_path = out_dir / "speed_soc.png"
    fig.savefig(speed_path, dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 5))
    hours = np.where(result.residence_s > 0, result.residence_s / 3600.0, np.nan)
    mesh = ax.pcolormesh(result.residence_speed_edges_rpm, result.residence_torque_edges_nm, hours.T, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="residence time [h]")
    ax.set_xlabel("machine speed [rpm]")
    ax.set_ylabel("machine torque [Nm]")
    ax.set_title("machine operating points")
    fig.tight_layout()
    residence_path = out_dir / "machine_residence.png"
    fig.savefig(residence_path, dpi=110)
    plt.close(fig)
    return [speed_path, residence_path]
