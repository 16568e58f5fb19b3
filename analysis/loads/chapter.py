"""The loads stage's report chapter: what a reader should take from its summary and figures."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..report.html import Section, deviation_pct

TITLE = "Load collectives at the wheel"


def loads_chapter(loads: dict, out_dir: Path) -> Section:
    """The report chapter from the stage's summary and the files in ``out_dir``."""
    section = Section(TITLE)
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
                     "generated vs measured": deviation_pct(value, cycle)})
    if rows:
        section.tables.append(("Damage-equivalent wheel torque ranges (per second of operation)", rows))
    comparison = out_dir / "comparison.csv"
    if comparison.is_file():
        levels, coverage = _comparison_rows(pd.read_csv(comparison))
        section.tables.append(("Measured against generated (a level exceeded some share of the time as a share of "
                               "the measured span between its 5 % and 95 % levels)", levels))
        if coverage:
            section.tables.append(("How the cycle covers the measured speed × torque residence", coverage))
    figures = sorted(out_dir.glob("*.png"))
    captions = {"time_at_level.png": "Time at level of wheel force, torque, speed and power.",
                "matrices.png": "Speed × torque residence time and rainflow range/mean matrices.",
                "crossings_damage.png": "Level crossings and damage-equivalent torques over the Wöhler exponent."}
    section.figures = [(path, captions.get(path.name, path.stem.replace("_", " "))) for path in figures]
    return section


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
                       "generated vs measured": deviation_pct(measured, generated)})
    spans = _level_spans(levels)
    for row in levels:
        quantity, exceeded, _ = row["criterion"].partition(" exceeded")
        span = spans.get(quantity) if exceeded else None
        if span:
            share = round((row["generated"] - row["measured"]) / span * 100, 1) + 0.0
            row["generated vs measured"] = f"{share:+.1f} % of span"
    return levels, coverage


def _level_spans(levels: list[dict]) -> dict[str, float]:
    """Per quantity, the measured span between the levels exceeded 5 % and 95 % of the time: every
    level of it is compared against that span, not against itself, since a level can be near zero
    (a wheel speed exceeded 95 % of the time, a force changing sign; cf. `markov.load_criteria`)."""
    found: dict[str, dict[str, float]] = {}
    for row in levels:
        quantity, exceeded, share = row["criterion"].partition(" exceeded ")
        if exceeded:
            found.setdefault(quantity, {})[share.split("%")[0]] = row["measured"]
    return {quantity: abs(shares["5"] - shares["95"]) for quantity, shares in found.items()
            if {"5", "95"} <= set(shares) and shares["5"] != shares["95"]}
