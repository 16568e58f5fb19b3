"""The run's report: one self-contained ``report.html`` that reads like the paper's results section.

The last file of the pipeline's output step. Chapters come from what the stages left in the summary
and the figures the output step drew; a stage that did not run gives no chapter and is named in
the lead.
"""

from __future__ import annotations

from pathlib import Path

from .chapters import (cycle_section, gradient_section, loads_section, mass_section, simulation_section,
                       simulation_skipped_section)
from ..design import design_chapter
from .drive import drive_section
from .html import Section, render

CHAPTERS = [("gradient", gradient_section), ("mass", mass_section), ("cycle", cycle_section),
            ("loads", loads_section), ("simulation", simulation_section), ("design", design_chapter)]


def build_report(signals, summary: dict, out_dir, title: str = "haulprofile report") -> str:
    sections: list[Section] = [drive_section(signals, summary)]
    missing = []
    skipped = summary.get("skipped", {})
    for key, chapter in CHAPTERS:
        if key in summary:
            sections.append(chapter(summary, out_dir))
        elif key == "simulation" and skipped.get("simulation"):
            sections.append(simulation_skipped_section(skipped["simulation"]))
        else:
            missing.append(key)
    lead = (f"{len(summary.get('ingest', {}).get('inputs', [])) or 'the'} input(s), "
            f"{summary.get('distance_km', 0):.1f} km in {summary.get('duration_s', 0) / 60:.0f} min.")
    if missing:
        lead += f" Not in this report (stage not run or lacking inputs): {', '.join(missing)}."
    return render(title, lead, sections)


def write_report(signals, summary: dict, directory, vehicle=None) -> str:
    """``report.html`` from the summary and the figures already written into ``directory``;
    returns its name."""
    title = "haulprofile report" + (f" — {vehicle.name}" if vehicle is not None else "")
    path = Path(directory) / "report.html"
    path.write_text(build_report(signals, summary, directory, title=title), encoding="utf-8")
    return path.name
