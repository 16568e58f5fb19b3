"""Report chapters for the estimation, cycle, load and simulation stages.

Each reads what its stage left in the run's summary and output directory (tables from
``summary.json``, figures the stage drew) and says in words what a reader should take from it.
A stage that did not run gives no chapter, and its absence is stated in the report's lead.
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from .html import Section


def _figures(out_dir: Path, names: list[tuple[str, str]]) -> list[tuple[Path, str]]:
    return [(out_dir / name, caption) for name, caption in names if (out_dir / name).is_file()]


def gradient_section(summary: dict, out_dir: Path) -> Section:
    g = summary["gradient"]
    smoother = g.get("smoother") or {}
    method = g.get("method", "paper")
    section = Section("Road gradient: barometer, IMU, map and GPS in one smoother" if method == "smoother"
                      else "Road gradient: map-matching fused with barometric height")
    section.kpis = [("sources", ", ".join(g["sources"])), ("gradient_pct from", method),
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
                               "along the route)", [{"source": k, "mean weight": round(v, 3)} for k, v in weights.items()]))
    noise = {k: v for k, v in smoother.items() if k.endswith(("_m", "_mps2", "_psd")) and k != "map_gated_km"
             and v is not None}
    if noise:
        section.tables.append(("Noise levels and calibrations the smoother took from this drive",
                               [{"quantity": k, "value": f"{v:.3g}"} for k, v in noise.items()]))
    section.notes.extend(g.get("notes", []))
    section.figures = _figures(out_dir, [("gradient.png", "Heights of each source; the smoother's source weights "
                                                          "along the route with the stretches where the map was gated "
                                                          "out (red) and the paper's w_map; the gradients of each "
                                                          "source, the paper's fusion and the smoother (cf. the "
                                                          "paper's Fig. 2).")])
    return section


def mass_section(summary: dict, out_dir: Path) -> Section:
    m = summary["mass"]
    section = Section("Vehicle mass per segment")
    rows = []
    for s in m["segments"]:
        rows.append({"from [s]": round(s["start_s"]), "to [s]": round(s["end_s"]), "samples": s["n_samples"],
                     "mass [kg]": s.get("mass_kg"), "± [kg] (1σ)": s.get("mass_uncertainty_kg"),
                     "IMU-based [kg]": s.get("mass_imu_kg"), "± IMU": s.get("mass_imu_uncertainty_kg"),
                     "gradient-based [kg]": s.get("mass_gradient_kg"), "± gradient": s.get("mass_gradient_uncertainty_kg"),
                     "LS [kg]": s.get("mass_ls_kg"), "± [kg]": s.get("uncertainty_kg"),
                     "RLS [kg]": s.get("mass_rls_kg"), "LM [kg]": s.get("mass_lm_kg"),
                     "truck's CAN [kg]": s.get("reported_mass_kg"),
                     "status": s["status"] + (f": {s['reason']}" if s.get("reason") else "")})
    section.paragraphs.append(
        "The mass changes only at standstill, so the drive is cut at stops and one mass is estimated per segment "
        "from equation (10) with least squares (9), recursive least squares with forgetting (11)–(13) and the "
        "damped Levenberg–Marquardt form (14). The ± column is one standard uncertainty of the LS estimate. "
        "A segment without enough excitation gets no number, and the status says why.")
    section.paragraphs.append(
        "The mass column is the joint estimate: all segments together with the drive's own rolling-resistance "
        "coefficient and drag area, from the accelerometer where there is one (it measures a + g sin α itself, "
        "so the mass does not inherit the gradient estimate's errors), else from wheel speed and the gradient. "
        "Samples whose force balance is broken (air compressor, fan, PTO, unflagged braking) get weight zero. "
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
    coefficients = [{"coefficient": name, "value": f"{entry['value']:.4g}",
                     "± (1σ)": f"{entry['std']:.2g}" if entry.get("std") is not None else "-",
                     "identified": "yes" if entry["identified"] else "no", "note": entry["reason"]}
                    for name, entry in road_load.items() if isinstance(entry, dict) and "identified" in entry]
    if coefficients:
        section.tables.append(("Road load estimated with the masses (shared by all segments)", coefficients))
    if m.get("rejected_by"):
        section.tables.append(("Why samples were left out of the regression (a sample may fail several tests)",
                               [{"filter": k, "samples": v} for k, v in m["rejected_by"].items()]))
    section.notes.extend(m.get("notes", []))
    section.figures = _figures(out_dir, [("mass.png", "Estimates over time by method, the truck's own CAN estimate "
                                                      "and the LS band of ±2 uncertainties (cf. the paper's Fig. 6).")])
    return section


def cycle_section(summary: dict, out_dir: Path) -> Section:
    c = summary["cycle"]
    section = Section("Representative driving cycle")
    refined = c.get("method") == "refined"
    section.kpis = [("score S (15)", f"{c['score']:.3f}"), ("valid on all criteria", "yes" if c["valid"] else "no"),
                    ("score without mass", f"{c.get('score_without_mass', float('nan')):.3f}"),
                    ("valid Monte Carlo candidates", f"{c.get('n_valid', '–')} of {c.get('n_candidates', '–')}")]
    if c.get("loads_within_allowance") is not None:
        section.kpis.append(("wheel loads within allowance", "yes" if c["loads_within_allowance"] else "no"))
    section.paragraphs.append(
        "States combine a speed class with a combined gradient-and-mass class (a 2D Markov chain); transitions "
        "counted in the measured drive are sampled by Monte Carlo into candidate cycles, scored with "
        "S = mean(d_i / d_max,i) over the criteria (eq. (15)). For reference, the paper's best cycle scored 1.39 "
        "with mass criteria and 0.245 without.")
    if refined:
        section.paragraphs.append(
            f"Selection: the Monte Carlo walks closest to validity were refined (windows of the walk re-drawn from "
            f"the chain, a change kept when it brings the walk closer to the criteria and to the measured drive's "
            f"wheel loads; {c.get('moves', 0)} moves each), so the cycle is still a walk of measured transitions. "
            f"The chosen one started at S = {c.get('start_score', float('nan')):.3f}.")
    else:
        section.paragraphs.append("Selection: the paper's, the valid candidate with the lowest S.")
    if not c["valid"]:
        section.notes.append(c.get("statement", "no candidate met every criterion"))
    rows = [{"criterion": name, "measured": v["measured"], "cycle": v["candidate"], "deviation": v["deviation"],
             "allowance": v["allowance"], "passed": bool(v["passed"])} for name, v in c["criteria"].items()]
    section.tables.append(("Criteria: the chosen cycle against the measured data", rows))
    if c.get("load_criteria"):
        section.tables.append(("Load criteria: the chosen cycle's wheel loads against the measured drive's", [
            {"criterion": name, "measured": v["measured"], "cycle": v["candidate"], "relative": v["relative"],
             "deviation": v["deviation"], "allowance": v["allowance"], "passed": bool(v["passed"])}
            for name, v in c["load_criteria"].items()]))
    if c.get("cycle_set"):
        spread = c["cycle_set"]["spread"]
        section.tables.append((f"Cycle set: {c['cycle_set']['n_cycles']} cycles, smallest and largest deviation", [
            {"criterion": name, "min": v["min"], "max": v["max"]} for name, v in spread["criteria"].items()]))
    section.figures = _figures(out_dir, [
        ("cycle.png", "The generated cycle's speed, gradient and mass over time, and measured against generated "
                      "distributions (cf. Fig. 7)."),
        ("cycle-scores.png", "Score S of every Monte Carlo candidate (how rare a good cycle is by lottery) and of "
                             "the chosen cycle(s).")])
    return section


def loads_section(summary: dict, out_dir: Path) -> Section:
    loads = summary["loads"]
    section = Section("Load collectives at the wheel")
    section.paragraphs.append(
        "Wheel force, torque, speed and power follow from the one vehicle model (equations (1)–(4)) with the "
        "estimated gradient and mass. Time-at-level histograms, the speed × torque residence matrix and rainflow "
        "counts (ASTM E1049) of the wheel torque are the design inputs; damage-equivalent torque ranges condense "
        "them per Wöhler exponent k. Measured and generated are compared so the cycle's representativeness for the "
        "powertrain is a number, not only a kinematic criterion.")
    rows = []
    measured, generated = loads.get("measured", {}), loads.get("generated", {})
    for k, value in measured.get("damage_equivalent_torque_range_nm", {}).items():
        cycle = generated.get("damage_equivalent_torque_range_nm", {}).get(k)
        rows.append({"Wöhler exponent k": int(k), "measured [kNm]": value / 1000,
                     "generated [kNm]": None if cycle is None else cycle / 1000,
                     "generated vs measured": _deviation(value, cycle)})
    if rows:
        section.tables.append(("Damage-equivalent wheel torque ranges (per second of operation)", rows))
    comparison = out_dir / "loads" / "comparison.csv"
    if comparison.is_file():
        levels, coverage = _comparison_rows(pd.read_csv(comparison))
        section.tables.append(("Measured against generated", levels))
        if coverage:
            section.tables.append(("How the cycle covers the measured speed × torque residence", coverage))
    figures = sorted((out_dir / "loads").glob("*.png")) if (out_dir / "loads").is_dir() else []
    captions = {"time_at_level.png": "Time at level of wheel force, torque, speed and power.",
                "matrices.png": "Speed × torque residence time and rainflow range/mean matrices.",
                "crossings_damage.png": "Level crossings and damage-equivalent torques over the Wöhler exponent."}
    section.figures = [(path, captions.get(path.name, path.stem.replace("_", " "))) for path in figures]
    return section


def _deviation(measured, generated) -> str:
    """Generated relative to measured, as a signed percentage ("–" where undefined)."""
    if measured is None or generated is None or not math.isfinite(measured) or not math.isfinite(generated) \
            or measured == 0:
        return "–"
    return f"{(generated / measured - 1) * 100:+.1f} %"


def _comparison_rows(frame: pd.DataFrame) -> tuple[list[dict], list[dict]]:
    """Rows of ``loads/comparison.csv`` for reading: levels in kN, kNm, kW with the deviation in
    percent (the damage-equivalent ranges have their own table); the residence measures, one number
    each, apart."""
    levels, coverage = [], []
    units = {"[N]": ("[kN]", 1e-3), "[Nm]": ("[kNm]", 1e-3), "[W]": ("[kW]", 1e-3)}
    for row in frame.to_dict("records"):
        name = str(row["criterion"])
        if name.startswith("damage-equivalent"):
            continue
        if name.startswith("speed x torque residence"):
            coverage.append({"measure": name.split(": ", 1)[-1].replace(" [-]", ""),
                             "share": f"{row['generated']:.1%}"})
            continue
        measured, generated = float(row["measured"]), float(row["generated"])
        for unit, (shown, scale) in units.items():
            if unit in name:
                name, measured, generated = name.replace(unit, shown), measured * scale, generated * scale
                break
        levels.append({"criterion": name, "measured": measured, "generated": generated,
                       "generated vs measured": _deviation(measured, generated)})
    return levels, coverage


SIMULATION_TITLE = "The electric truck on this work"


def simulation_skipped_section(reason: str) -> Section:
    """The simulation chapter when the stage could not run: why, instead of empty numbers."""
    section = Section(SIMULATION_TITLE)
    section.notes.append(f"No simulation: {reason}.")
    return section


def simulation_section(summary: dict, out_dir: Path) -> Section:
    s = summary["simulation"]
    section = Section(SIMULATION_TITLE)
    measured = s.get("measured_drive")
    per_km = [(f"at the battery, {s['cycle']}", f"{s['battery_kwh_per_km']:.3f} kWh/km")]
    if measured:
        per_km.append((f"at the battery, {measured['cycle']}", f"{measured['battery_kwh_per_km']:.3f} kWh/km"))
    section.kpis = per_km + [
        ("positive at the wheels", f"{s['wheel_positive_kwh_per_km']:.3f} kWh/km"),
        ("recuperated at the wheels", f"{s['recuperated_at_wheel_kwh']:.1f} kWh"),
        ("state of charge", f"{s['initial_soc']:.0%} → {s['final_soc']:.0%}"),
        ("time below target speed", f"{s['missed_target_s']:.0f} s")]
    section.paragraphs.append(
        f"The target battery-electric powertrain of the vehicle file drove the {s['cycle']} "
        f"({s['distance_km']:.1f} km at {s['mean_mass_kg'] / 1000:.1f} t) in a forward simulation with a driver "
        "model, machine torque and power limits, recuperation up to its limit and a battery with internal "
        "resistance.")
    if measured:
        rows = [{"drive": run["cycle"], "distance [km]": run["distance_km"], "duration [min]": run["duration_s"] / 60,
                 "mean mass [t]": run["mean_mass_kg"] / 1000, "battery [kWh/km]": run["battery_kwh_per_km"],
                 "positive at the wheels [kWh/km]": run["wheel_positive_kwh_per_km"],
                 "time below target [s]": run["missed_target_s"]} for run in (s, measured)]
        section.tables.append(("Energy per km: the generated cycle against the measured drive it stands for", rows))
    if s.get("soc_below_minimum"):
        section.notes.append("The battery reached its minimum state of charge: the truck could not finish this work.")
    if s.get("missed_target_intervals"):
        section.notes.append(f"The truck missed the target speed in {s['missed_target_intervals']} interval(s), "
                             f"by up to {s['max_speed_deficit_mps'] * 3.6:.1f} km/h (simulation/misses.csv).")
    section.figures = _figures(out_dir / "simulation", [
        ("speed_soc.png", "Target and simulated speed, and the state of charge."),
        ("machine_residence.png", "Machine operating points: residence time over speed and torque.")])
    return section
