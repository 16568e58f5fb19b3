"""Figures of the design: the Pareto plot, and the drives' operating points over candidates' envelopes."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..loads.collectives import wheel_loads  # noqa: E402
from . import components as C  # noqa: E402

KMH = 3.6


def draw_pareto(result, out: Path) -> list[str]:
    o = result.outcome
    fig, ax = plt.subplots(figsize=(8.5, 5))
    bad = ~o.feasible & (o.objectives[:, 0] < 100)
    ax.scatter(o.objectives[bad, 1] / 1000, o.objectives[bad, 0], s=4, c="0.75", label="infeasible")
    ax.scatter(o.objectives[o.feasible, 1] / 1000, o.objectives[o.feasible, 0], s=6, c="C0", label="feasible")
    front = o.objectives[o.pareto]
    ax.plot(front[:, 1] / 1000, front[:, 0], "-o", c="C1", ms=3, label="Pareto front")
    if o.chosen is not None:
        ax.plot(o.objectives[o.chosen, 1] / 1000, o.objectives[o.chosen, 0], "*", c="C3", ms=16, label="chosen")
    ref = result.reference
    if ref and np.isfinite(ref["battery_kwh_per_km"]):
        ax.plot(ref["cost_eur"] / 1000, ref["battery_kwh_per_km"], "s", c="k", ms=8, label="vehicle file's")
    if o.feasible.any():
        f = o.objectives[o.feasible]
        ax.set_ylim(f[:, 0].min() * 0.97, f[:, 0].max() * 1.03)
    ax.set_xlabel("component cost proxy [k EUR]")
    ax.set_ylabel("battery energy [kWh/km]")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.set_title(f"{len(o.x)} candidates, {int(o.feasible.sum())} feasible")
    fig.tight_layout()
    fig.savefig(out / "pareto.png", dpi=110)
    plt.close(fig)
    return ["pareto.png"]


def draw_envelopes(result, out: Path) -> list[str]:
    """Wheel force over speed the drives asked for (estimate mass), under the largest wheel force
    of the chosen concept, a few other Pareto concepts and the vehicle file's powertrain."""
    vehicle = result.vehicle
    fig, ax = plt.subplots(figsize=(9.5, 5))
    for k, (name, drive) in enumerate(result.drives.items()):
        loads = wheel_loads(drive["time_s"], drive["speed_mps"], drive["accel_mps2"], drive["gradient_pct"],
                            drive["mass_kg"], vehicle)
        step = max(1, len(loads) // 4000)
        ax.scatter(loads["speed_mps"][::step] * KMH, loads["wheel_force_n"][::step] / 1000, s=2, alpha=0.4,
                   c=f"C{k}", label=name)
    speed = np.linspace(0.0, result.options.legal_top_speed_mps * 1.1, 120)
    e = result.evaluator
    picks = list(result.outcome.pareto[:: max(1, len(result.outcome.pareto) // 4)])
    for rank, i in enumerate(picks):
        c = e.decode(result.outcome.x[[i]])
        force = C.wheel_force_limit_n(speed, C.size(c, e.voltage_v, e.resistance), vehicle.wheel_radius_m)[0]
        chosen = i == result.outcome.chosen
        ax.plot(speed * KMH, force / 1000, lw=2.2 if chosen else 0.9, c="C3" if chosen else "0.4",
                label="chosen concept" if chosen else ("Pareto concepts" if rank == 0 else None))
    if result.outcome.chosen is not None and result.outcome.chosen not in picks:
        c, s = result.chosen()
        ax.plot(speed * KMH, C.wheel_force_limit_n(speed, s, vehicle.wheel_radius_m)[0] / 1000, lw=2.2, c="C3",
                label="chosen concept")
    ep = vehicle.electric_powertrain
    if ep is not None:
        ratios = np.asarray(ep.gear_ratios) * (ep.axle_ratio or vehicle.axle_ratio or 1.0)
        omega = np.maximum(speed, 0.05)[:, None] / vehicle.wheel_radius_m * ratios[None, :]
        torque = np.where(omega <= ep.machine_max_speed_rpm * 2 * np.pi / 60,
                          np.minimum(ep.machine_max_torque_nm, ep.machine_max_power_w / omega), 0.0)
        force = (torque * ratios * vehicle.driveline_efficiency / vehicle.wheel_radius_m).max(axis=1)
        ax.plot(speed * KMH, force / 1000, "k--", lw=1.2, label="vehicle file's powertrain")
    t = result.targets
    ax.plot([result.options.design_grade_speed_mps * KMH], [t["design_grade_force_n"] / 1000], "v", c="C3",
            ms=9, label=f"design grade {result.options.design_grade_pct:g} %")
    ax.plot([0.0], [t["startability_force_n"] / 1000], "^", c="C3", ms=9,
            label=f"start on {result.options.startability_grade_pct:g} %")
    ax.set_xlabel("speed [km/h]")
    ax.set_ylabel("wheel force [kN]")
    ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]))
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.set_title("operating points of the drives under the concepts' traction envelopes")
    fig.tight_layout()
    fig.savefig(out / "envelopes.png", dpi=110)
    plt.close(fig)
    return ["envelopes.png"]
