"""Report chapter on the measured drive (paper Fig. 5): speed, height, gradient, mass, engine speed
and fuel rate over time, as a figure and as a zoomable chart."""

from __future__ import annotations

import numpy as np

from .html import Section
from .zoom import zoom_chart

BLUE, AMBER, PALE = "#0969da", "#bf8700", "#80b3ec"
MASS_LINE = "estimated (joint fit per segment)"
CAN_LINE = "vehicle's own estimate (CVW)"
PANELS = [("speed_mps", "speed [km/h]", 3.6), ("gradient_pct", "gradient [%]", 1.0), ("height_m", "height [m]", 1.0),
          ("mass_kg", "mass [t]", 1e-3), ("engine_speed_rpm", "engine speed [rpm]", 1.0),
          ("fuel_rate_lph", "fuel rate [L/h]", 1.0)]
"""(column, axis label, scale) of each panel, drawn where the column holds any value."""


def _panels(signals) -> list[tuple[str, str, float]]:
    return [(column, label, scale) for column, label, scale in PANELS
            if column in signals and signals[column].notna().any()]


def mass_band_kg(signals, summary: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """±2σ of each mass segment's estimate along the time base (NaN outside segments with one),
    or None when the summary holds no segment uncertainty."""
    time = signals["time_s"].to_numpy(float)
    low, high = np.full(len(time), np.nan), np.full(len(time), np.nan)
    for segment in (summary.get("mass") or {}).get("segments", []):
        mass, sigma = segment.get("mass_kg"), segment.get("mass_uncertainty_kg")
        if mass is None or sigma is None:
            continue
        inside = (time >= segment["start_s"]) & (time <= segment["end_s"])
        low[inside], high[inside] = mass - 2 * sigma, mass + 2 * sigma
    return (low, high) if np.isfinite(low).any() else None


def drive_figure(signals, summary: dict | None = None):
    """The drive's signals over time, one panel each (shared time axis); the mass with its ±2σ band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    time_min = signals["time_s"].to_numpy() / 60.0
    panels = _panels(signals)
    figure, axes = plt.subplots(len(panels), 1, figsize=(10, 1.6 * len(panels) + 0.6), sharex=True, squeeze=False,
                                layout="constrained")
    band = mass_band_kg(signals, summary or {})
    for ax, (column, label, scale) in zip(axes[:, 0], panels):
        if column != "mass_kg":
            ax.plot(time_min, signals[column].to_numpy() * scale, lw=0.7, color=BLUE)
        else:
            ax.plot(time_min, signals[column].to_numpy() * scale, lw=0.9, color=BLUE, label=MASS_LINE)
            if band is not None:
                ax.fill_between(time_min, band[0] * scale, band[1] * scale, color=BLUE, alpha=0.15, lw=0,
                                label="±2σ of the segment's estimate")
            if "reported_mass_kg" in signals:
                ax.plot(time_min, signals["reported_mass_kg"].to_numpy() * scale, lw=0.7, color=AMBER,
                        label=CAN_LINE)
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [min]")
    figure.suptitle("The measured drive")
    return figure


def drive_chart(signals, summary: dict | None = None) -> str:
    """The same panels as a zoomable chart (`zoom.zoom_chart`); the mass with its ±2σ band as two
    pale lines."""
    panels = []
    band = mass_band_kg(signals, summary or {})
    for column, label, scale in _panels(signals):
        if column != "mass_kg":
            panels.append((label, [(label.split(" [")[0], signals[column].to_numpy(float) * scale, BLUE)]))
            continue
        lines = [(MASS_LINE, signals[column].to_numpy(float) * scale, BLUE)]
        if band is not None:
            lines += [("±2σ of the segment's estimate", band[0] * scale, PALE), ("", band[1] * scale, PALE)]
        if "reported_mass_kg" in signals:
            lines.append((CAN_LINE, signals["reported_mass_kg"].to_numpy(float) * scale, AMBER))
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
    odometer = summary.get("odometer") or {}
    if odometer.get("corrected"):
        section.kpis.append(("wheel speed against GPS", f"{odometer['scale_pct']:+.2f} %"))
    section.notes.extend(f"{note[0].upper()}{note[1:]}." for note in odometer.get("notes", []))
    if "valid" in signals:
        invalid = float(1 - signals["valid"].mean())
        if invalid > 0:
            section.notes.append(f"{invalid:.1%} of the time base lies in gaps of the log (no data, not interpolated).")
    names = ", ".join(label.split(" [")[0] for _, label, _ in _panels(signals))
    section.figures.append((drive_figure(signals, summary), f"{names[0].upper()}{names[1:]} over time (cf. the paper's Fig. 5)."))
    section.blocks.append((drive_chart(signals, summary), "The same signals to zoom into: the mouse wheel zooms the time axis, "
                                                 "dragging pans, a double click shows the whole drive."))
    return section
