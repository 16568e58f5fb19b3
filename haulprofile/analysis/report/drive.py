"""Report chapter on the measured drive (paper Fig. 5): speed, height, gradient, mass, engine speed
and fuel rate over time, as a figure and as a zoomable chart."""

from __future__ import annotations

import numpy as np

from .html import Section
from .zoom import zoom_chart

BLUE, AMBER = "#0969da", "#bf8700"
PANELS = [("speed_mps", "speed [km/h]", 3.6), ("gradient_pct", "gradient [%]", 1.0), ("height_m", "height [m]", 1.0),
          ("mass_kg", "mass [t]", 1e-3), ("engine_speed_rpm", "engine speed [rpm]", 1.0),
          ("fuel_rate_lph", "fuel rate [L/h]", 1.0)]
"""(column, axis label, scale) of each panel, drawn where the column holds any value."""


def _panels(signals) -> list[tuple[str, str, float]]:
    return [(column, label, scale) for column, label, scale in PANELS
            if column in signals and signals[column].notna().any()]


def drive_figure(signals):
    """The drive's signals over time, one panel each (shared time axis)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    time_min = signals["time_s"].to_numpy() / 60.0
    panels = _panels(signals)
    figure, axes = plt.subplots(len(panels), 1, figsize=(10, 1.6 * len(panels) + 0.6), sharex=True, squeeze=False,
                                layout="constrained")
    for ax, (column, label, scale) in zip(axes[:, 0], panels):
        ax.plot(time_min, signals[column].to_numpy() * scale, lw=0.7, color=BLUE)
        if column == "mass_kg" and "reported_mass_kg" in signals:
            ax.plot(time_min, signals["reported_mass_kg"].to_numpy() * scale, lw=0.7, color=AMBER,
                    label="vehicle's own estimate (CVW)")
            ax.legend(loc="best", fontsize=8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [min]")
    figure.suptitle("The measured drive")
    return figure


def drive_chart(signals) -> str:
    """The same panels as a zoomable chart (`zoom.zoom_chart`)."""
    panels = []
    for column, label, scale in _panels(signals):
        lines = [("estimated" if column == "mass_kg" else column, signals[column].to_numpy(float) * scale, BLUE)]
        if column == "mass_kg" and "reported_mass_kg" in signals:
            lines.append(("vehicle's own estimate (CVW)", signals["reported_mass_kg"].to_numpy(float) * scale, AMBER))
        panels.append((label, lines))
    return zoom_chart(signals["time_s"].to_numpy(float), panels)


def drive_section(signals, summary: dict) -> Section:
    speed = signals["speed_mps"].to_numpy()
    time = signals["time_s"].to_numpy()
    moving = speed > 0.5
    starts = int(np.count_nonzero(moving[1:] & ~moving[:-1]))
    section = Section("The drive")
    section.kpis = [("duration", f"{(time[-1] - time[0]) / 60:.0f} min")]
    if "distance_m" in signals:
        section.kpis.append(("distance", f"{signals['distance_m'].iloc[-1] / 1000:.1f} km"))
    section.kpis += [("mean speed while moving", f"{np.nanmean(speed[moving]) * 3.6:.1f} km/h" if moving.any() else "–"),
                     ("maximum speed", f"{np.nanmax(speed) * 3.6:.1f} km/h" if np.isfinite(speed).any() else "–"),
                     ("starts from standstill", str(starts))]
    if "valid" in signals:
        invalid = float(1 - signals["valid"].mean())
        if invalid > 0:
            section.notes.append(f"{invalid:.1%} of the time base lies in gaps of the log (no data, not interpolated).")
    names = ", ".join(label.split(" [")[0] for _, label, _ in _panels(signals))
    section.figures.append((drive_figure(signals), f"{names[0].upper()}{names[1:]} over time (cf. the paper's Fig. 5)."))
    section.blocks.append((drive_chart(signals), "The same signals to zoom into: the mouse wheel zooms the time axis, "
                                                 "dragging pans, a double click shows the whole drive."))
    return section
