"""The gradient stage's report chapter: what a reader should take from its summary and figures."""

from __future__ import annotations

from pathlib import Path

from ..report.html import Section, figures_present
from ..report.labels import label

TITLE = "Road gradient"
SOURCES = {"baro": "barometer", "map": "elevation model (DEM)", "imu": "accelerometer (IMU)", "gps": "GPS altitude"}


def gradient_chapter(g: dict, out_dir: Path) -> Section:
    """The report chapter from the stage's summary and the files in ``out_dir``."""
    if g.get("method") == "flat_road":
        section = Section(f"{TITLE}: taken as flat, not estimated")
        section.kpis = [("gradient", "0 % (assumed)")]
        section.paragraphs.append("The road was taken as flat (--flat-road): this log has no source of road height "
                                  "the run could use, or the user chose so. Wheel loads, the cycle's gradient "
                                  "classes and the energy per km leave out climbing and descending; on a hilly "
                                  "route they are too small.")
        return section
    smoother = g.get("smoother") or {}
    method = g.get("method", "paper")
    section = Section("Road gradient: barometer, IMU, map and GPS in one smoother" if method == "smoother"
                      else "Road gradient: map-matching fused with barometric height")
    section.kpis = [("sources", ", ".join(SOURCES.get(k, k) for k in g["sources"])), ("gradient from", "the smoother" if method == "smoother" else "the paper's fusion (8)"),
                    ("gradient range", f"{g['gradient_pct']['min']:+.1f} … {g['gradient_pct']['max']:+.1f} %"),
                    ("climbed", f"{g['height_gain_m']:.0f} m"), ("paper's mean w_map", f"{g['mean_map_weight']:.2f}")]
    if g.get("sensor_set"):
        section.kpis.append(("sensor set", g["sensor_set"]))
    if smoother.get("map_gated_km") is not None:
        section.kpis.append(("map gated out", f"{smoother['map_gated_km']:.2f} km"))
    if smoother.get("imu_bias_mps2") is not None:
        section.kpis.append(("IMU bias (pitch + sensor)", f"{smoother['imu_bias_mps2']:+.3f} m/s²"))
    section.paragraphs.append(
        "The smoother (the default gradient_pct) estimates road height, gradient, barometric weather drift, the "
        "accelerometer's bias and the elevation model's own error together, forward and backward over the driven "
        "distance. Each source counts by the noise it shows in this drive; the elevation model is checked against "
        "barometer and IMU and gated out where it disagrees beyond its error model — a bridge over a valley, a "
        "tunnel, a cutting. The paper's fusion (8) (barometer 0.7, map by GPS accuracy alone) is kept beside it as "
        "gradient_paper_pct; the figure shows both.")
    weights = smoother.get("mean_weights")
    if weights:
        section.tables.append(("Each source's mean share of the information on the gradient (the figure shows it "
                               "along the route)", [{"source": SOURCES.get(k, k), "mean weight": round(v, 3)} for k, v in weights.items()]))
    noise = {k: v for k, v in smoother.items() if k.endswith(("_m", "_mps2", "_psd")) and k != "map_gated_km"
             and v is not None}
    if noise:
        section.tables.append(("Noise levels and calibrations the smoother took from this drive",
                               [{"quantity": label(k)[0], "value": f"{v * label(k)[2]:.3g}", "unit": label(k)[1]}
                                for k, v in noise.items()]))
    section.notes.extend(g.get("notes", []))
    section.figures = figures_present(out_dir, [("gradient.png", "Heights of each source; the smoother's source weights "
                                                          "along the route with the stretches where the map was gated "
                                                          "out (red) and the paper's w_map; the gradients of each "
                                                          "source, the paper's fusion and the smoother (cf. the "
                                                          "paper's Fig. 2).")])
    return section
