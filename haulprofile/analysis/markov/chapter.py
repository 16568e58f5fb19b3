"""The cycle stage's report chapter: what a reader should take from its summary and figures."""

from __future__ import annotations

from pathlib import Path

from ..report.html import Section, figures_present

TITLE = "Representative driving cycle"


def cycle_chapter(c: dict, out_dir: Path) -> Section:
    """The report chapter from the stage's summary and the files in ``out_dir``."""
    section = Section(TITLE)
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
    section.figures = figures_present(out_dir, [
        ("cycle.png", "The generated cycle's speed, gradient and mass over time, and measured against generated "
                      "distributions (cf. Fig. 7)."),
        ("cycle-scores.png", "Score S of every Monte Carlo candidate (how rare a good cycle is by lottery) and of "
                             "the chosen cycle(s).")])
    return section
