"""``fleet-report.html``: what a fleet operator reads, per truck (a ``LOGDIR``) and per vehicle class
(the trucks sharing a vehicle file): distance per day, the mass the trucks carried, energy per km
and range with the vehicle file's battery on the group's cycle, the cycles and their scores.

Built from the fleet's reduced statistics and cycles in memory, with `report.html` (the run
report's page, offline, figures embedded).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..report.html import Section, render
from ..report.labels import labelled

UNKNOWN = "–"


@dataclass
class Energy:
    """The group's cycle driven by the vehicle file's electric powertrain."""

    battery_kwh_per_km: float
    range_km: float
    usable_kwh: float


def cycle_energy(group) -> Energy | None:
    """Battery energy per km of the group's cycle and the range of the vehicle file's battery on
    it (usable energy between the initial and the minimum state of charge); None without a cycle
    or an ``[electric_powertrain]``."""
    powertrain = group.vehicle.electric_powertrain
    if group.cycle is None or powertrain is None:
        return None
    from ..simulate.model import simulate_cycle
    from ..simulate.stage import selected_cycle

    numbers = simulate_cycle(selected_cycle(group.cycle, f"{group.name}'s cycle"), group.vehicle).numbers
    usable = powertrain.battery_capacity_kwh * (powertrain.initial_soc - powertrain.min_soc)
    per_km = numbers["battery_kwh_per_km"]
    return Energy(per_km, usable / per_km if per_km and per_km > 0 else float("nan"), usable)


def operation(group, energy: Energy | None) -> dict:
    """What ``fleet-summary.json`` holds of the report's numbers for one truck (``operation``)."""
    km_day, days = _km_per_day(group)
    return {"days_with_driving": days, "km_per_day": km_day if days else None,
            "cycle_battery_kwh_per_km": energy.battery_kwh_per_km if energy else None,
            "range_km": energy.range_km if energy else None, "usable_battery_kwh": energy.usable_kwh if energy else None}


def _km_per_day(group) -> tuple[float, int]:
    """Distance per calendar day with driving (UTC, from the logs' wall-clock times) and the days."""
    days = len(group.dates)
    if not days or group.statistics is None:
        return float("nan"), days
    return group.statistics.totals["distance_km"] / days, days


def _masses(group) -> np.ndarray:
    """Each mass segment's mass [kg], from the truck's shared fit where there is one, else the logs'."""
    segments = group.road_load.get("segments") or (group.statistics.mass_segments if group.statistics else [])
    return np.array([s["mass_kg"] for s in segments if s.get("mass_kg") is not None], float)


def _median_mass_t(groups, given_mass_kg: float | None):
    if given_mass_kg is not None:
        return f"{given_mass_kg / 1000:.1f} (given)"
    masses = np.concatenate([_masses(g) for g in groups]) if groups else np.array([])
    return float(np.median(masses)) / 1000 if masses.size else UNKNOWN


def _row(name: str, vehicle: str, groups: list, energies: dict, given_mass_kg: float | None) -> dict:
    statistics = [g.statistics for g in groups if g.statistics is not None]
    km = sum(s.totals["distance_km"] for s in statistics)
    days = sum(len(g.dates) for g in groups)
    wheel = sum(s.totals["positive_wheel_energy_kwh"] for s in statistics)
    with_loads = sum(s.totals["loads_s"] for s in statistics) > 0
    energy = [energies[g.name] for g in groups if energies.get(g.name) is not None]
    return {"truck or class": name, "vehicle file": vehicle, "logs": sum(len(s.logs) for s in statistics),
            "failed logs": sum(len(g.failed) for g in groups), "distance [km]": km,
            "driving [h]": sum(s.totals["driving_s"] for s in statistics) / 3600,
            "days with driving": days or UNKNOWN, "km/day": km / days if days else UNKNOWN,
            "median mass [t]": _median_mass_t(groups, given_mass_kg),
            "positive wheel energy, measured [kWh/km]": wheel / km if km > 0 and with_loads else UNKNOWN,
            "battery on the cycle [kWh/km]": float(np.mean([e.battery_kwh_per_km for e in energy])) if energy
            else UNKNOWN,
            "range on the cycle [km]": float(np.mean([e.range_km for e in energy])) if energy else UNKNOWN}


def mass_figure(group):
    """Distribution of the segments' masses of one truck."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    masses = _masses(group) / 1000
    figure, ax = plt.subplots(figsize=(7, 3), layout="constrained")
    ax.hist(masses, bins=max(5, min(30, masses.size)), color="#0969da")
    ax.axvline(group.vehicle.curb_mass_kg / 1000, color="#57606a", ls="--", label="curb mass")
    ax.set_xlabel("mass of a segment between stops [t]")
    ax.set_ylabel("segments")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False, fontsize=8)
    return figure


def cycle_figure(group):
    """The group's cycle: speed, gradient and mass over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cycle = group.cycle
    minutes = cycle["time_s"].to_numpy(float) / 60
    figure, axes = plt.subplots(3, 1, figsize=(9, 5), sharex=True, layout="constrained")
    for ax, (column, label, scale) in zip(axes, (("speed_mps", "speed [km/h]", 3.6),
                                                 ("gradient_pct", "gradient [%]", 1.0), ("mass_kg", "mass [t]", 1e-3))):
        if column in cycle:
            ax.plot(minutes, cycle[column].to_numpy(float) * scale, lw=0.8, color="#0969da")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [min]")
    return figure


def truck_section(group, energy: Energy | None) -> Section:
    section = Section(f"Truck {group.name} ({group.vehicle.name})")
    statistics = group.statistics
    if statistics is None:
        section.notes.append("No log of this truck could be read: " +
                             "; ".join(f"{log}: {error}" for log, error in group.failed))
        return section
    km_day, days = _km_per_day(group)
    section.kpis = [("logs", str(len(statistics.logs))), ("distance", f"{statistics.totals['distance_km']:.1f} km"),
                    ("km/day", f"{km_day:.0f}" if days else UNKNOWN)]
    if energy is not None:
        section.kpis += [("battery on the cycle", f"{energy.battery_kwh_per_km:.3f} kWh/km"),
                         ("range on the cycle", f"{energy.range_km:.0f} km")]
    if group.selection:
        section.kpis += [("cycle score S (15)", f"{group.selection['score']:.3f}"),
                         ("cycle valid on all criteria", "yes" if group.selection["valid"] else "no")]
    if not days:
        section.notes.append("km/day not known: the logs carry no wall-clock time (signals tables without "
                             "wall_time_ns).")
    if energy is not None:
        section.paragraphs.append(
            f"Range: the vehicle file's battery ({energy.usable_kwh:.0f} kWh usable between its initial and "
            f"minimum state of charge) over the battery energy per km of this truck's cycle, driven by the "
            f"simulation of the run report.")
    if group.failed:
        section.notes.append(f"{len(group.failed)} log(s) failed: " +
                             "; ".join(f"{log}: {error}" for log, error in group.failed))
    if group.error:
        section.notes.append(f"No cycle: {group.error}")
    elif group.selection:
        failed = group.selection.get("failed") or []
        section.paragraphs.append(
            f"Cycle: the refined selection of analyze run (Monte Carlo walks refined towards the criteria and "
            f"the truck's summed wheel loads, ending at a stop) on the summed transitions of every log, score "
            f"{group.selection['score']:.3f}, " + ("valid on every criterion." if group.selection["valid"] else
                                                 f"not valid on: {', '.join(labelled(n) for n in failed)}."))
    if _masses(group).size:
        section.figures.append((mass_figure(group), "Mass of each segment between stops (the truck's shared fit "
                                                    "where the logs allowed one, else each log's own)."))
    if group.cycle is not None:
        section.figures.append((cycle_figure(group), "The truck's representative cycle."))
    return section


def fleet_report(fleet, given_mass_kg: float | None = None, energies: dict | None = None) -> str:
    """The page: the fleet table (per truck, per vehicle class), then a chapter per truck;
    ``given_mass_kg``: the mass every log was given instead of an estimate; ``energies``: each
    truck's `cycle_energy` (computed here when not given)."""
    if energies is None:
        energies = {group.name: cycle_energy(group) for group in fleet.groups}
    overview = Section("The fleet")
    overview.tables.append(("Per truck (a log directory)", [_row(g.name, g.vehicle.name, [g], energies, given_mass_kg)
                                                            for g in fleet.groups]))
    classes: dict[str, list] = {}
    for group in fleet.groups:
        classes.setdefault(group.vehicle.name, []).append(group)
    overview.tables.append(("Per vehicle class (the trucks sharing a vehicle file)",
                            [_row(f"{len(groups)} truck(s)", name, groups, energies, given_mass_kg)
                             for name, groups in classes.items()]))
    overview.paragraphs.append(
        "km/day: distance over the calendar days (UTC) on which the truck moved. Energy per km at the wheel is "
        "measured (the logs' wheel loads); at the battery it is the truck's cycle driven by the vehicle file's "
        "electric powertrain, and the range is its usable battery energy over that.")
    logs = sum(len(g.statistics.logs) for g in fleet.groups if g.statistics is not None)
    lead = f"{len(fleet.groups)} truck(s), {logs} log(s) analysed on the {fleet.executor} executor."
    return render("haulprofile fleet report", lead, [overview] + [truck_section(g, energies[g.name])
                                                                  for g in fleet.groups])


def write_fleet_report(fleet, out_dir: Path, given_mass_kg: float | None = None, energies: dict | None = None) -> Path:
    path = Path(out_dir) / "fleet-report.html"
    path.write_text(fleet_report(fleet, given_mass_kg, energies), encoding="utf-8")
    return path
