"""Report chapter on the measured drive (paper Fig. 5): speed, height, gradient and mass over time."""

from __future__ import annotations

import numpy as np

from .html import Section


def drive_figure(signals):
    """Speed, road height/gradient and mass over time, one panel each (shared time axis)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    time_min = signals["time_s"].to_numpy() / 60.0
    panels = [("speed_mps", "speed [km/h]", 3.6)]
    if "gradient_pct" in signals:
        panels.append(("gradient_pct", "gradient [%]", 1.0))
    if "height_m" in signals:
        panels.append(("height_m", "height [m]", 1.0))
    if "mass_kg" in signals:
        panels.append(("mass_kg", "mass [t]", 1e-3))
    figure, axes = plt.subplots(len(panels), 1, figsize=(10, 1.9 * len(panels) + 0.6), sharex=True, squeeze=False)
    for ax, (column, label, scale) in zip(axes[:, 0], panels):
        ax.plot(time_min, signals[column].to_numpy() * scale, lw=0.7, color="#0969da")
        if column == "mass_kg" and "reported_mass_kg" in signals:
            ax.plot(time_min, signals["reported_mass_kg"].to_numpy() * scale, lw=0.7, color="#bf8700",
                    label="vehicle's own estimate (CVW)")
            ax.legend(loc="best", fontsize=8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [min]")
    figure.suptitle("The measured drive")
    return figure


def drive_section(signals, summary: dict) -> Section:
    speed = signals["speed_mps"].to_numpy()
    time = signals["time_s"].to_numpy()
    moving = speed > 0.5
    starts = int(np.count_nonzero(moving[1:] & ~moving[:-1]))
    distance_km = float(signals["distance_m"].iloc[-1] / 1000) if "distance_m" in signals else float("nan")
    duration_h = float((time[-1] - time[0]) / 3600)
    section = Section("The drive")
    section.kpis = [("duration", f"{duration_h * 60:.0f} min"), ("distance", f"{distance_km:.1f} km"),
                    ("mean speed while moving", f"{np.nanmean(speed[moving]) * 3.6:.1f} km/h" if moving.any() else "–"),
                    ("maximum speed", f"{np.nanmax(speed) * 3.6:.1f} km/h"), ("starts from standstill", str(starts))]
    if "valid" in signals:
        invalid = float(1 - signals["valid"].mean())
        if invalid > 0:
            section.notes.append(f"{invalid:.1%} of the time base lies in gaps of the log (no data, not interpolated).")
    section.figures.append((drive_figure(signals), "Speed, road gradient, height and estimated mass over time "
                                                   "(cf. the paper's Fig. 5)."))
    return section
