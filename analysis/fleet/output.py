"""Files of a fleet run: per group ``<out>/<group>/`` the cycle (CSV, Parquet, VECTO .vdri), the
summed transition counts (``counts.npz``, read back with `read_counts`), the load histograms
(``histograms/*.csv``), mass per segment and ``fleet-summary.json``; ``<out>/fleet-summary.json``
lists the groups and every failed log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from haulprofile.contract.private_files import make_dirs

from ..markov import ClassWidths, TransitionCounts, write_cycle
from .. import jsonable

VALUE_NAMES = {"rainflow_range_mean_counts": "cycles", "level_crossings_torque": "upward_crossings"}


def road_load_line(road_load: dict) -> str:
    """One line: the truck's shared c_r, c_d·A (± 1σ or not identifiable) and torque gain."""
    parts = []
    for name, label, digits in (("rolling_resistance_coefficient", "c_r", 5), ("drag_area_m2", "c_d·A", 2)):
        entry = road_load[name]
        parts.append(f"{label} {entry['value']:.{digits}f} ± {entry['std']:.{digits}f}" if entry["identified"]
                     else f"{label} not identifiable (vehicle file's {entry['value']:.{digits}f})")
    gain = road_load["torque_gain"]
    parts.append(f"torque gain {gain['gain']:.4f} ± {100 * gain['relative_std']:.2f} % "
                 + ("(assumed)" if gain["calibrated_from"] is None else "(from the weighing)"))
    return f"shared over {road_load['logs']} logs: " + ", ".join(parts)


def write_counts(counts: TransitionCounts, path: Path) -> Path:
    np.savez_compressed(path, widths=np.array([counts.widths.speed_kmh, counts.widths.gradient_pct,
                                               counts.widths.mass_kg]),
                        from_key=counts.from_key, to_key=counts.to_key, count=counts.count, moments=counts.moments,
                        totals=np.array([counts.n_samples, counts.n_dropped, counts.n_closed]),
                        start_key=counts.start_key, start_count=counts.start_count)
    return path


def read_counts(path: str | Path) -> TransitionCounts:
    """Transition counts written by `write_counts` (a group's ``counts.npz``)."""
    with np.load(path) as data:
        n_samples, n_dropped, n_closed = (int(x) for x in data["totals"])
        return TransitionCounts(ClassWidths(*(float(w) for w in data["widths"])), data["from_key"], data["to_key"],
                                data["count"], data["moments"], n_samples, n_dropped, n_closed, data["start_key"],
                                data["start_count"])


def group_summary(group, spec) -> dict:
    statistics = group.statistics
    summary = {"group": group.name, "vehicle": group.vehicle.name, "logs": statistics.logs if statistics else [],
               "failed": [{"log": log, "error": error} for log, error in group.failed], "error": group.error}
    if statistics is not None:
        summary.update(
            totals=statistics.totals,
            damage_equivalent_torque_range_nm={str(k): v for k, v in statistics.damage_equivalent_torque_nm().items()},
            class_widths=spec.widths.as_dict(), load_bins=spec.bins.as_dict(), mass_segments=statistics.mass_segments,
            notes=statistics.notes)
        if statistics.counts is not None:
            summary["transitions"] = {"pairs": len(statistics.counts), "count": int(statistics.counts.count.sum()),
                                      "samples_1hz": statistics.counts.n_samples,
                                      "dropped": statistics.counts.n_dropped, "loops_closed": statistics.counts.n_closed}
    if group.road_load:
        summary["road_load"] = {**group.road_load, "per_log": statistics.road_load_logs if statistics else []}
    if group.selection:
        summary["cycle"] = {**group.selection, "duration_s": spec.duration_s}
    return summary


def write_group(group, spec, out_dir: Path, operation: dict | None = None) -> dict:
    """Every file of one group; returns its summary (also written as ``fleet-summary.json``), with
    ``operation`` (`report.operation`: km/day, energy per km and range) where given."""
    group_dir = out_dir / group.name
    make_dirs(group_dir)
    files = {}
    statistics = group.statistics
    if group.cycle is not None:
        files.update({kind: path.name for kind, path in write_cycle(group.cycle, group_dir).items()})
    if statistics is not None:
        if statistics.counts is not None:
            files["counts"] = write_counts(statistics.counts, group_dir / "counts.npz").name
        hist_dir = group_dir / "histograms"
        make_dirs(hist_dir)
        for name, histogram in statistics.histograms.items():
            value = VALUE_NAMES.get(name, "time_s")
            histogram.frame(value).to_csv(hist_dir / f"{name}.csv", index=False)
        damage = statistics.damage_equivalent_torque_nm()
        pd.DataFrame({"woehler_exponent": list(damage), "damage_equivalent_torque_range_nm": list(damage.values()),
                      "equivalent_cycles": statistics.totals["loads_s"]}).to_csv(
            hist_dir / "damage_equivalent_torque.csv", index=False)
        files["histograms"] = "histograms/"
        if statistics.mass_segments:
            pd.DataFrame(statistics.mass_segments).to_csv(group_dir / "mass_segments.csv", index=False)
            files["mass_segments"] = "mass_segments.csv"
    if group.road_load.get("segments"):
        pd.DataFrame(group.road_load["segments"]).to_csv(group_dir / "truck_masses.csv", index=False)
        files["truck_masses"] = "truck_masses.csv"
    summary = {**group_summary(group, spec), **({"operation": operation} if operation else {}), "files": files}
    (group_dir / "fleet-summary.json").write_text(jsonable.dumps(summary, indent=2))
    return summary


def write_fleet(fleet, spec, out_dir: Path, say=print) -> dict:
    from ..pipeline import Options
    from .report import cycle_energy, operation, write_fleet_report

    make_dirs(out_dir)
    energies = {group.name: cycle_energy(group) for group in fleet.groups}
    groups = [write_group(group, spec, out_dir, operation(group, energies[group.name])) for group in fleet.groups]
    summary = {"executor": fleet.executor, "dem_dir": spec.dem_dir, "groups": [
        {key: g.get(key) for key in ("group", "vehicle", "error", "totals", "transitions", "failed", "operation")}
        | {"cycle": g.get("cycle", {}).get("statement"), "logs": len(g["logs"]),
           "road_load": {k: v for k, v in g.get("road_load", {}).items() if k not in ("segments", "per_log")}}
        for g in groups]}
    (out_dir / "fleet-summary.json").write_text(jsonable.dumps(summary, indent=2))
    mass = getattr(Options.of(spec.options), "mass", None)
    say(f"fleet: report {write_fleet_report(fleet, out_dir, getattr(mass, 'known_mass_kg', None), energies)}")
    for g in groups:
        line = g.get("cycle", {}).get("statement") or g["error"]
        say(f"fleet: {g['group']}: {len(g['logs'])} logs, {len(g['failed'])} failed; cycle: {line}; "
            f"wrote {out_dir / g['group']}")
        road_load = g.get("road_load", {})
        if "error" in road_load:
            say(f"fleet: {g['group']}: road load: {road_load['error']}")
        elif road_load.get("segments"):
            say(f"fleet: {g['group']}: {road_load_line(road_load)}")
    return summary
