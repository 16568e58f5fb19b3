"""The mass stage's report chapter: what a reader should take from its summary and figures."""

from __future__ import annotations

from pathlib import Path

from ..report.html import Section, figures_present
from ..report.labels import labelled, significant

TITLE = "Vehicle mass per segment"


def mass_chapter(m: dict, out_dir: Path) -> Section:
    """The report chapter from the stage's summary and the files in ``out_dir``."""
    section = Section(TITLE)
    if m.get("given_mass_kg") is not None:
        section.kpis = [("total mass (given, not estimated)", f"{m['given_mass_kg'] / 1000:.2f} t")]
        section.paragraphs.append("A known total mass was given for the whole drive (--mass-kg, a weighing or the "
                                  "vehicle's papers), so nothing was estimated: every result after this chapter uses "
                                  "it.")
        return section
    rows = []
    for s in m["segments"]:
        mass, sigma = rounded(s.get("mass_kg"), s.get("mass_uncertainty_kg"))
        imu, imu_sigma = rounded(s.get("mass_imu_kg"), s.get("mass_imu_uncertainty_kg"))
        gradient, gradient_sigma = rounded(s.get("mass_gradient_kg"), s.get("mass_gradient_uncertainty_kg"))
        ls, ls_sigma = rounded(s.get("mass_ls_kg"), s.get("uncertainty_kg"))
        rows.append({"from [s]": round(s["start_s"]), "to [s]": round(s["end_s"]), "samples": s["n_samples"],
                     "mass [kg]": mass, "± [kg] (1σ)": sigma, "IMU-based [kg]": imu, "± IMU [kg]": imu_sigma,
                     "gradient-based [kg]": gradient, "± gradient [kg]": gradient_sigma,
                     "LS [kg]": ls, "± LS [kg]": ls_sigma,
                     "RLS [kg]": rounded(s.get("mass_rls_kg"), s.get("uncertainty_kg"))[0],
                     "LM [kg]": rounded(s.get("mass_lm_kg"), s.get("uncertainty_kg"))[0],
                     "auxiliaries [kW]": auxiliary_power(s),
                     "truck's CAN [kg]": s.get("reported_mass_kg"),
                     "status": s["reason"] if s.get("reason") else s["status"].replace("_", " ")})
    section.paragraphs.append(
        "The mass changes only at standstill, so the drive is cut at stops and one mass is estimated per segment "
        "from equation (10) with least squares (9), recursive least squares with forgetting (11)–(13) and the "
        "damped Levenberg–Marquardt form (14). The ± column is one standard uncertainty of the LS estimate. "
        "A segment without enough excitation gets no number, and the status says why.")
    section.paragraphs.append(
        "The mass column is the joint estimate: all segments together with the drive's own rolling-resistance "
        "coefficient and drag area, from the accelerometer where there is one (it measures a + g sin α itself, "
        "so the mass does not inherit the gradient estimate's errors), else from wheel speed and the gradient. "
        "Samples whose force balance is broken (air compressor, fan, PTO, unflagged braking) get weight zero; "
        "an auxiliary that runs through most of a segment is fitted as that segment's auxiliary power (what the "
        "engine gives it reads at the wheel as a force falling with speed), and where the drive cannot tell it "
        "from the mass its prior is in the ± column. "
        "A gain error in the engine's torque report cannot be told apart from mass within one drive: unless a "
        "weighed segment calibrates it (--known-mass), it is part of the ± column.")
    road_load = m.get("road_load") or {}
    section.kpis = [("segments", str(len(m["segments"]))), ("samples used", f"{m['samples_used']:,}")]
    if road_load:
        section.kpis.append(("mass from", road_load.get("regressor", "")))
        gain = road_load.get("torque_gain", {})
        section.kpis.append(("torque gain", f"{gain.get('gain', 1.0):.4f} ± {100 * gain.get('relative_std', 0):.1f} %"
                             + ("" if gain.get("calibrated_from") else " (not calibrated)")))
    section.tables.append(("Per-segment estimates", rows))
    coefficients = [{"coefficient": labelled(name), "value": f"{entry['value']:.4g}",
                     "± (1σ)": f"{entry['std']:.2g}" if entry.get("std") is not None else "-",
                     "identified": "yes" if entry["identified"] else "no", "note": entry["reason"]}
                    for name, entry in road_load.items() if isinstance(entry, dict) and "identified" in entry]
    if coefficients:
        section.tables.append(("Road load estimated with the masses (shared by all segments)", coefficients))
    if m.get("rejected_by"):
        section.tables.append(("Why samples were left out of the regression (a sample may fail several tests)",
                               [{"filter": k, "samples": v} for k, v in m["rejected_by"].items()]))
    section.notes.extend(m.get("notes", []))
    section.figures = figures_present(out_dir, [("mass.png", "Estimates over time by method, the truck's own CAN estimate "
                                                      "and the LS band of ±2 uncertainties (cf. the paper's Fig. 6).")])
    return section


def rounded(mass_kg: float | None, sigma_kg: float | None) -> tuple[float | None, float | None]:
    """A mass and its uncertainty as a reader takes them: the uncertainty to two significant
    digits, the mass to the same decimal place (15 793.4 ± 624.7 → 15 790 ± 620)."""
    sigma = significant(sigma_kg)
    if mass_kg is None or sigma is None or not sigma > 0:
        return mass_kg, sigma
    from math import floor, log10

    return round(mass_kg, 1 - floor(log10(sigma))), sigma


def auxiliary_power(segment: dict) -> str | None:
    """A segment's fitted auxiliary power as "P ± σ" in kW ("(prior)" where the drive did not identify it)."""
    power, std = segment.get("aux_power_w"), segment.get("aux_power_std_w")
    if power is None or std is None:
        return None
    return f"{power / 1000:.1f} ± {std / 1000:.1f}" + ("" if segment.get("aux_power_identified") else " (prior)")
