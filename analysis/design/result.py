"""The design stage's result in memory (`DesignResult`), its summary and its files (`write_design`)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import pandas as pd

from . import components as C
from . import requirements as R
from .chapter import machines_text
from .choice import Criterion, criterion, near_optimal
from .evaluate import Evaluator
from .options import DesignOptions
from .search import SearchOutcome

FOLDER = "design"
MAP_FILE = "concept-efficiency-map.csv"
FILES = ("pareto.csv", "candidates.csv", "requirements.csv", "concept.toml", MAP_FILE, "pareto.png", "envelopes.png")
"""Every name the design may write into its folder."""


@dataclass
class DesignResult:
    """Requirements (ranges over drives and mass cases), the searched candidates, the chosen concept."""

    options: DesignOptions
    vehicle: object
    evaluator: Evaluator
    outcome: SearchOutcome
    ranges: dict
    """Wheel requirement key -> {"value", "low", "high"} (SI units, key names say which)."""
    per_drive: dict
    targets: dict
    """Static targets at the gross mass: forces at the wheel [N] (`requirements.static_requirements`)."""
    daily_distance_m: float
    energy_margin: float
    """Positive wheel energy at the heaviest case over the estimate [-]: the range constraint's margin."""
    mass_sigma_kg: float
    drives: dict = field(repr=False, default_factory=dict)
    exclusions: dict = field(default_factory=dict)
    reference: dict | None = None
    loads: dict = field(default_factory=dict)
    search_s: float = 0.0
    @property
    def criterion(self) -> Criterion:
        """How the concept was chosen, and the lifetime energy cost per kWh/km for the cost of ownership."""
        return criterion(self.options, self.daily_distance_m)

    @property
    def feasible(self) -> bool:
        return self.outcome.chosen is not None

    def chosen(self):
        """(candidates, sizing) of the chosen concept alone (None when nothing was feasible)."""
        if not self.feasible:
            return None
        c = self.evaluator.decode(self.outcome.x[[self.outcome.chosen]])
        return c, C.size(c, self.evaluator.voltage_v, self.evaluator.resistance)

    def concept_vehicle(self, map_csv: str | None = None):
        c, s = self.chosen()
        return self.evaluator.powertrain(c, s, 0, map_csv)

    def candidates_frame(self) -> pd.DataFrame:
        """Every simulated candidate: its variables, sizing, objectives, constraints and status."""
        e = self.evaluator
        c = e.decode(self.outcome.x)
        s = C.size(c, e.voltage_v, e.resistance)
        frame = pd.DataFrame({
            "topology": [C.TOPOLOGIES[t] for t in c.topology], "machines": c.machines, "gears": c.speeds,
            "machine_peak_power_w": c.machine_power_w, "machine_max_speed_rpm": c.machine_max_speed_rpm,
            "low_ratio": c.low_ratio, "top_ratio": c.top_ratio, "inverter_current_a": c.inverter_current_a,
            "battery_energy_kwh": c.battery_energy_j / 3.6e6, "total_peak_torque_nm": s.peak_torque_nm,
            "total_peak_power_w": s.peak_power_w, "driveline_efficiency": s.driveline_efficiency,
            "battery_kwh_per_km": self.outcome.objectives[:, 0], "cost_eur": self.outcome.objectives[:, 1],
            "powertrain_mass_kg": s.mass_kg, "feasible": self.outcome.feasible})
        for k, name in enumerate(self.outcome.constraint_names):
            frame[f"g_{name.replace(' ', '_')}"] = self.outcome.constraints[:, k]
        return frame

    def concept_summary(self) -> dict | None:
        if not self.feasible:
            return None
        c, s = self.chosen()
        o, i = self.options, self.outcome.chosen
        kwh_per_km = float(self.outcome.objectives[i, 0])
        daily_kwh = kwh_per_km * self.energy_margin * self.daily_distance_m / 1000.0
        break_kwh = o.break_charging_s * o.break_charger_power_w / 3.6e6
        ratios = s.ratios[0][np.isfinite(s.ratios[0])]
        g = self.outcome.constraints[i]
        shaft = [R.shaft_requirements(self.ranges_at("estimate"), float(r), float(s.driveline_efficiency[0]),
                                      self.vehicle.wheel_radius_m) for r in ratios]
        return {
            "topology": C.TOPOLOGIES[int(c.topology[0])], "machines": int(c.machines[0]), "gears": int(c.speeds[0]),
            "machine_peak_power_w": float(c.machine_power_w[0]), "total_peak_power_w": float(s.peak_power_w[0]),
            "total_peak_torque_nm": float(s.peak_torque_nm[0]), "total_continuous_power_w": float(s.continuous_power_w[0]),
            "total_continuous_torque_nm": float(s.continuous_torque_nm[0]),
            "machine_max_speed_rpm": float(c.machine_max_speed_rpm[0]), "total_ratios": [float(r) for r in ratios],
            "driveline_efficiency": float(s.driveline_efficiency[0]), "inverter_current_a": float(c.inverter_current_a[0]),
            "battery_energy_kwh": float(c.battery_energy_j[0] / 3.6e6), "battery_kwh_per_km": kwh_per_km,
            "cost_eur": float(s.cost_eur[0]), "powertrain_mass_kg": float(s.mass_kg[0]),
            "ownership_cost_eur": float(self.criterion.ownership_eur(self.outcome.objectives[i])[0]),
            "daily_energy_kwh": daily_kwh,
            "usable_energy_kwh": float(c.battery_energy_j[0] / 3.6e6 * o.usable_soc_window * (1 - o.ageing_reserve)),
            "depot_charging_power_w": max(daily_kwh - break_kwh, 0.0) * 3.6e6 / o.depot_charging_s,
            "closest_constraint": self.outcome.constraint_names[int(np.argmax(g))],
            "closest_constraint_margin": float(-g.max()),
            "shaft_requirements": shaft,
        }

    def near_optimal_summary(self) -> dict | None:
        """The feasible concepts within ``near_optimal_share`` of the chosen one's cost of ownership:
        how many, and the range of their key figures (how sharply the criterion defines the choice)."""
        if not self.feasible:
            return None
        out = self.outcome
        index = near_optimal(self.criterion, out.objectives, out.feasible, out.chosen, self.options.near_optimal_share)
        c = self.evaluator.decode(out.x[index])
        s = C.size(c, self.evaluator.voltage_v, self.evaluator.resistance)

        def span(values) -> list[float]:
            return [float(np.min(values)), float(np.max(values))]

        return {"share": self.options.near_optimal_share, "candidates": int(len(index)),
                "topologies": sorted({C.TOPOLOGIES[int(t)] for t in c.topology}),
                "machines": sorted({int(m) for m in c.machines}), "gears": sorted({int(g) for g in c.speeds}),
                "total_peak_power_w": span(s.peak_power_w), "total_continuous_power_w": span(s.continuous_power_w),
                "battery_energy_kwh": span(c.battery_energy_j / 3.6e6),
                "battery_kwh_per_km": span(out.objectives[index, 0]), "cost_eur": span(out.objectives[index, 1]),
                "ownership_cost_eur": span(self.criterion.ownership_eur(out.objectives[index]))}

    def ranges_at(self, case: str) -> dict:
        first = next(iter(self.per_drive))
        return self.per_drive[first][case]

    def summary(self) -> dict:
        """Strict-JSON-able numbers of the design (docs/summary-json.md, ``design``)."""
        out = self.outcome
        concept = self.concept_summary()
        return {
            "drives": list(self.per_drive),
            "cycles": list(self.evaluator.batch.names),
            "mass_sigma_kg": self.mass_sigma_kg,
            "mass_sigmas": self.options.mass_sigmas,
            "daily_distance_km": self.daily_distance_m / 1000.0,
            "energy_margin": self.energy_margin,
            "requirements": self.ranges,
            "static": self.targets,
            "damage_equivalent_wheel_torque_range_nm": self.loads.get("measured", {}).get(
                "damage_equivalent_torque_range_nm"),
            "candidates": int(len(out.x)),
            "feasible_candidates": int(out.feasible.sum()),
            "pareto_size": int(len(out.pareto)),
            "search_s": self.search_s,
            "candidates_per_s": len(out.x) / self.search_s if self.search_s > 0 else None,
            "chosen_by": self.criterion.name,
            "ownership": {"energy_price_eur_per_kwh": self.options.energy_price_eur_per_kwh,
                          "service_life_years": self.options.service_life_years,
                          "operating_days_per_year": self.options.operating_days_per_year,
                          "energy_eur_per_kwh_per_km": self.criterion.eur_per_kwh_per_km},
            "concept": concept,
            "near_optimal": self.near_optimal_summary(),
            "reference": self.reference,
            "excluded": self.exclusions,
            "feasible": self.feasible,
            "binding_constraint": self.exclusions.get("binding_constraint"),
        }


def concept_toml(result: DesignResult, map_csv: str) -> str:
    """The concept as a whole vehicle file (the user's tables, the concept's driveline efficiency
    and ``[electric_powertrain]``) that `analyze simulate --vehicle` reads."""
    import tomli_w

    vehicle = result.concept_vehicle(map_csv)

    def table(obj, skip=()):
        return {f.name: (list(v) if isinstance(v, tuple) else v) for f in fields(obj)
                if f.name not in skip and (v := getattr(obj, f.name)) is not None}

    data = {"vehicle": table(vehicle, ("engine", "electric_powertrain", "max_payload_kg"))}
    if vehicle.max_payload_kg is not None:
        data["load"] = {"max_payload_kg": vehicle.max_payload_kg}
    if vehicle.engine is not None:
        data["engine"] = table(vehicle.engine)
    data["electric_powertrain"] = table(vehicle.electric_powertrain)
    s = result.concept_summary()
    head = (f"# Concept by `analyze design`: {s['topology']}, {machines_text(s)} peak, {s['gears']} gear(s), "
            f"{s['battery_energy_kwh']:.0f} kWh.\n"
            "# Two machines appear as one of their summed torque and power (they share the torque equally).\n"
            "# driveline_efficiency is the concept's gearbox and axle efficiency.\n\n")
    return head + tomli_w.dumps(data)


def write_design(result: DesignResult, folder: Path, figures: bool = True) -> list[str]:
    """``design/`` in ``folder``: pareto.csv, candidates.csv, requirements.csv, concept.toml with its
    efficiency map, pareto.png and envelopes.png; returns the names written, relative to ``folder``."""
    out = Path(folder) / FOLDER
    out.mkdir(parents=True, exist_ok=True)
    return [f"{FOLDER}/{n}" for n in write_into(result, out, figures)]


def write_into(result: DesignResult, out: Path, figures: bool = True) -> list[str]:
    """The design's files directly in ``out``; returns their names."""
    from .figures import draw_envelopes, draw_pareto

    out = Path(out)
    frame = result.candidates_frame()
    frame.iloc[result.outcome.pareto].to_csv(out / "pareto.csv", index=False)
    frame.to_csv(out / "candidates.csv", index=False)
    rows = [{"requirement": k, "value": v["value"], "low": v["low"], "high": v["high"]} for k, v in result.ranges.items()]
    rows += [{"requirement": k, "value": v, "low": v, "high": v} for k, v in result.targets.items()]
    pd.DataFrame(rows).to_csv(out / "requirements.csv", index=False)
    names = ["pareto.csv", "candidates.csv", "requirements.csv"]
    if result.feasible:
        c, s = result.chosen()
        speed, torque, eff = result.evaluator.machine_map(s, 0)
        grid_speed, grid_torque = np.meshgrid(speed * 60.0 / (2 * np.pi), torque, indexing="ij")
        pd.DataFrame({"speed_rpm": grid_speed.ravel(), "torque_nm": grid_torque.ravel(),
                      "efficiency": eff.ravel()}).to_csv(out / MAP_FILE, index=False)
        (out / "concept.toml").write_text(concept_toml(result, MAP_FILE))
        names += ["concept.toml", MAP_FILE]
    if figures:
        names += draw_pareto(result, out) + draw_envelopes(result, out)
    return names
