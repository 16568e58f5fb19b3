"""The report chapter "What this application needs", from the design's summary and figures."""

from __future__ import annotations

import math
from pathlib import Path

from ..report.html import Section

TITLE = "What this application needs"

ROWS = [
    ("peak_wheel_torque_nm", "peak wheel torque", "kNm", 1e-3),
    ("peak_wheel_power_w", "peak wheel power", "kW", 1e-3),
    ("peak_regen_wheel_power_w", "peak braking power at the wheels", "kW", 1e-3),
    ("rms_wheel_torque_10s_nm", "RMS wheel torque, 10 s", "kNm", 1e-3),
    ("rms_wheel_torque_60s_nm", "RMS wheel torque, 60 s", "kNm", 1e-3),
    ("rms_wheel_torque_600s_nm", "RMS wheel torque, 10 min", "kNm", 1e-3),
    ("rms_wheel_torque_1800s_nm", "RMS wheel torque, 30 min", "kNm", 1e-3),
    ("mean_wheel_power_60s_w", "mean |wheel power|, 60 s", "kW", 1e-3),
    ("mean_wheel_power_600s_w", "mean |wheel power|, 10 min", "kW", 1e-3),
    ("mean_wheel_power_1800s_w", "mean |wheel power|, 30 min", "kW", 1e-3),
    ("wheel_torque_exceeded_0.05_nm", "wheel torque exceeded 5 % of moving time", "kNm", 1e-3),
    ("damage_equivalent_wheel_torque_range_k5_nm", "damage-equivalent torque range (k = 5, 1 Hz)", "kNm", 1e-3),
    ("positive_wheel_kwh_per_km", "positive wheel energy", "kWh/km", 1.0),
    ("top_speed_driven_mps", "top speed driven", "km/h", 3.6),
    ("max_gradient_pct", "steepest grade driven", "%", 1.0),
    ("accel_0_50_kmh_s", "0-50 km/h as driven (fastest)", "s", 1.0),
    ("accel_0_80_kmh_s", "0-80 km/h as driven (fastest)", "s", 1.0),
]


def machines_text(concept: dict) -> str:
    """``2 x 300 kW``, or ``1 x 258 kW (233 kW with its inverter)`` where the inverter's current
    caps the machines' peak power: the machine's rating alone would overstate what the concept has."""
    machines, each_kw = concept["machines"], concept["machine_peak_power_w"] / 1000
    total_kw = concept.get("total_peak_power_w", machines * concept["machine_peak_power_w"]) / 1000
    text = f"{machines} x {each_kw:.0f} kW"
    if total_kw < machines * each_kw - 0.5:
        text += f" ({total_kw:.0f} kW with {'its inverter' if machines == 1 else 'their inverters'})"
    return text


def _fmt(value, scale) -> str:
    if value is None or not math.isfinite(value):
        return "–"
    return f"{value * scale:,.0f}" if abs(value * scale) >= 1000 else f"{value * scale:.3g}"


def design_chapter(d: dict, out_dir: Path) -> Section:
    """The chapter from the stage's summary (``summary["design"]``) and the files in its folder ``out_dir``."""
    section = Section(TITLE)
    req = d["requirements"]
    rows = [{"requirement": label, "unit": unit, "nominal": _fmt(req[key]["value"], scale),
             "range": f"{_fmt(req[key]['low'], scale)} … {_fmt(req[key]['high'], scale)}"}
            for key, label, unit, scale in ROWS if key in req]
    st = d["static"]
    rows += [{"requirement": label, "unit": "kN", "nominal": _fmt(st[key], 1e-3), "range": "at gross mass"}
             for key, label in (("design_grade_force_n", "wheel force on the design grade"),
                                ("startability_force_n", "wheel force to start on the startability grade"),
                                ("top_speed_force_n", "wheel force at the legal top speed"))]
    section.paragraphs.append(
        f"Requirements of {', '.join(d['drives'])} at the wheel, each at the mass estimate and "
        f"±{d['mass_sigmas']:g} σ ({d['mass_sigma_kg']:.0f} kg), as the nominal (first drive, estimate) and the "
        f"range over all drives and mass cases. Static targets hold at the gross mass "
        f"({st['gross_mass_kg'] / 1000:.1f} t).")
    section.tables.append(("Requirements at the wheel, with their ranges", rows))
    concept = d.get("concept")
    section.kpis = [("candidates simulated", f"{d['candidates']}"), ("feasible", f"{d['feasible_candidates']}"),
                    ("search", f"{d['search_s']:.0f} s")]
    if concept is None:
        section.notes.append(f"No feasible concept in the design space: the binding constraint is "
                             f"{d['binding_constraint']}.")
    else:
        section.kpis += [("concept", f"{concept['topology']}, {machines_text(concept)}, {concept['gears']} gear(s)"),
                         ("battery", f"{concept['battery_energy_kwh']:.0f} kWh"),
                         ("energy", f"{concept['battery_kwh_per_km']:.3f} kWh/km")]
        section.paragraphs.append(
            f"NSGA-II searched topology, machines, gears, machine size and speed, ratios, inverter current and "
            f"battery energy; each candidate drove {', '.join(d['cycles'])} in the simulator. The chosen concept "
            f"({d['chosen_by']}) needs {concept['daily_energy_kwh']:.0f} kWh a day over "
            f"{d['daily_distance_km']:.0f} km, of {concept['usable_energy_kwh']:.0f} kWh usable with the reserves, "
            f"and {concept['depot_charging_power_w'] / 1000:.0f} kW at the depot. Its tightest constraint is "
            f"{concept['closest_constraint']}.")
        own, near = d.get("ownership"), d.get("near_optimal")
        if near and own:
            section.paragraphs.append(
                f"Cost of ownership: components plus the battery's energy at {own['energy_price_eur_per_kwh']:g} EUR/kWh "
                f"over {own['service_life_years']:g} years of {own['operating_days_per_year']:g} days: "
                f"{concept['ownership_cost_eur'] / 1000:.1f} kEUR for this concept. The {near['candidates']} feasible "
                f"concepts within {100 * near['share']:g} % of it ({', '.join(near['topologies'])}; "
                f"{'/'.join(map(str, near['machines']))} machine(s); {'/'.join(map(str, near['gears']))} gear(s)) span "
                f"{near['total_peak_power_w'][0] / 1000:.0f}–{near['total_peak_power_w'][1] / 1000:.0f} kW peak and "
                f"{near['battery_energy_kwh'][0]:.0f}–{near['battery_energy_kwh'][1]:.0f} kWh: the criterion cannot "
                f"tell them apart closer than that.")
        ref = d.get("reference") or {}
        compare = [("peak power [kW]", concept["total_peak_power_w"] / 1000, ref.get("machine_peak_power_w", 0) / 1000),
                   ("peak torque at the machine(s) [Nm]", concept["total_peak_torque_nm"], ref.get("machine_peak_torque_nm")),
                   ("maximum speed [rpm]", concept["machine_max_speed_rpm"], ref.get("machine_max_speed_rpm")),
                   ("battery [kWh]", concept["battery_energy_kwh"], ref.get("battery_energy_kwh")),
                   ("battery energy [kWh/km]", concept["battery_kwh_per_km"], ref.get("battery_kwh_per_km")),
                   ("component cost proxy [EUR]", concept["cost_eur"], ref.get("cost_eur")),
                   ("cost of ownership [EUR]", concept.get("ownership_cost_eur"), ref.get("ownership_cost_eur"))]
        section.tables.append(("The chosen concept against the vehicle file's powertrain (same cycles)",
                               [{"quantity": q, "concept": a, "vehicle file": b if ref else None} for q, a, b in compare]))
        section.tables.append(("At the machine shaft, per gear of the concept (nominal drive)",
                               [{"total ratio": round(s["ratio"], 2), "peak torque [Nm]": s["peak_machine_torque_nm"],
                                 "RMS torque 60 s [Nm]": s.get("rms_machine_torque_60s_nm"),
                                 "speed at top speed driven [rpm]": s["machine_speed_at_top_speed_rpm"]}
                                for s in concept["shaft_requirements"]]))
    excluded = d["excluded"]["by_constraint"]
    section.tables.append(("Why candidates failed: how many broke each constraint, and for how many it was the only one",
                           [{"constraint": k, "violated": v["violated"], "only violation": v["only_violation"]}
                            for k, v in excluded.items()]))
    regions = d["excluded"]["by_region"]
    section.tables.append(("Regions of the design space", [
        {"region": k, "candidates": v["candidates"], "feasible": v["feasible"],
         "most violated": v.get("most_violated", "")} for k, v in regions.items()]))
    folder = Path(out_dir)
    section.figures = [(folder / name, caption) for name, caption in (
        ("pareto.png", "Energy per km against the component cost proxy of every candidate; the Pareto front and "
                       "the chosen concept."),
        ("envelopes.png", "Wheel force over speed the drives asked for, under the traction envelopes of Pareto "
                          "concepts, the chosen one and the vehicle file's powertrain."))
        if (folder / name).is_file()]
    return section
