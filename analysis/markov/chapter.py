"""The cycle stage's report chapter: what a reader should take from its summary and figures."""

from __future__ import annotations

from pathlib import Path

from ..report.html import Section, figures_present
from ..report.labels import label, labelled
from .load_criteria import GATED

TITLE = "Representative driving cycle"


def cycle_chapter(c: dict, out_dir: Path) -> Section:
    """The report chapter from the stage's summary and the files in ``out_dir``."""
    section = Section(TITLE)
    refined = c.get("method") == "refined"
    section.kpis = [("score S (15)", f"{c['score']:.3f}"), ("valid on all criteria", "yes" if c["valid"] else "no"),
                    ("score without mass", f"{c.get('score_without_mass', float('nan')):.3f}"),
                    ("valid Monte Carlo candidates", f"{c.get('n_valid', '–')} of {c.get('n_candidates', '–')}")]
    if c.get("loads_within_allowance") is not None:
        section.kpis.append(("required wheel-load criteria within allowance",
                             "yes" if c["loads_within_allowance"] else "no"))
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
    section.tables.append(("Criteria: the chosen cycle against the measured data (deviation relative to the "
                           "measured value or its scale, eq. (15))", [
        {"criterion": labelled(name), "measured": v["measured"] * label(name)[2],
         "cycle": v["candidate"] * label(name)[2], "deviation": percent(v["deviation"]),
         "allowance": percent(v["allowance"]), "passed": bool(v["passed"])} for name, v in c["criteria"].items()]))
    if c.get("load_criteria"):
        section.tables.append(("Load criteria: the chosen cycle's wheel loads against the measured drive's (the "
                               "residence distance is scored, not required)", [
            {"criterion": labelled(name), "measured": v["measured"] * label(name)[2],
             "cycle": v["candidate"] * label(name)[2], "cycle vs measured": percent(v["relative"], signed=True),
             "deviation": percent(v["deviation"]), "allowance": percent(v["allowance"]),
             "passed": bool(v["passed"]) if name in GATED else "scored only"}
            for name, v in c["load_criteria"].items()]))
    if c.get("cycle_set"):
        spread = c["cycle_set"]["spread"]
        section.tables.append((f"Cycle set: {c['cycle_set']['n_cycles']} cycles, smallest and largest deviation", [
            {"criterion": labelled(name), "smallest": percent(v["min"]), "largest": percent(v["max"])}
            for name, v in spread["criteria"].items()]))
    section.figures = figures_present(out_dir, [
        ("cycle.png", "The generated cycle's speed, gradient and mass over time, and measured against generated "
                      "distributions (cf. Fig. 7)."),
        ("cycle-scores.png", "Score S of every Monte Carlo candidate (how rare a good cycle is by lottery) and of "
                             "the chosen cycle(s).")])
    return section


def percent(share: float | None, signed: bool = False) -> str:
    """A share as a percentage for the tables ("–" where undefined)."""
    if share is None or share != share:
        return "–"
    return f"{share * 100:+.1f} %" if signed else f"{share * 100:.1f} %"
