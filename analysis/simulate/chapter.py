"""The simulate stage's report chapter: what a reader should take from its summary and figures."""

from __future__ import annotations

from pathlib import Path

from ..report.html import Section, figures_present

TITLE = "The electric truck on this work"
ENERGY_ALLOWANCE = 0.05
"""The cycle's battery energy per km may differ from the measured drive's by this share before the
report flags it (the positive wheel energy criterion's allowance, `markov.load_criteria`)."""


def simulation_chapter(s: dict, out_dir: Path) -> Section:
    """The report chapter from the stage's summary and the files in ``out_dir``."""
    section = Section(TITLE)
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
    if measured and (flag := energy_flag(s, measured)):
        section.notes.append(flag)
    if s.get("soc_below_minimum"):
        section.notes.append("The battery reached its minimum state of charge: the truck could not finish this work.")
    if s.get("missed_target_intervals"):
        section.notes.append(misses_line(s) + " (simulation/misses.csv).")
    section.figures = figures_present(out_dir, [
        ("speed_soc.png", "Target and simulated speed, and the state of charge."),
        ("machine_residence.png", "Machine operating points: residence time over speed and torque.")])
    return section


def misses_line(s: dict) -> str:
    """How often the truck fell behind its target speed, counting only misses a driver notices
    (at least ``missed_target_long_min_s``) and the shorter blips apart."""
    long, every = s.get("missed_target_long_intervals", s["missed_target_intervals"]), s["missed_target_intervals"]
    threshold = s.get("missed_target_long_min_s", 0.0)
    line = (f"The truck stayed below the target speed for at least {threshold:g} s in {long} "
            f"interval(s) ({s['missed_target_s']:.0f} s below target in all, by up to "
            f"{s['max_speed_deficit_mps'] * 3.6:.1f} km/h)")
    return line + (f"; {every - long} shorter blip(s) are not counted" if every > long else "")


def energy_flag(s: dict, measured: dict) -> str | None:
    """A line when the cycle's battery energy per km is more than `ENERGY_ALLOWANCE` off the measured
    drive's: a drive sized on the cycle would get a battery that much too small or too large."""
    cycle, drive = s["battery_kwh_per_km"], measured["battery_kwh_per_km"]
    if not drive or not abs(cycle / drive - 1) > ENERGY_ALLOWANCE:
        return None
    return (f"The cycle needs {cycle:.3f} kWh/km at the battery, {(cycle / drive - 1) * 100:+.1f} % against the "
            f"measured drive's {drive:.3f} kWh/km (allowed ±{ENERGY_ALLOWANCE:.0%}): a battery or range sized on "
            f"the cycle is off by about as much.")
