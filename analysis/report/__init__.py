"""The run's report: one self-contained ``report.html`` that reads like the paper's results section.

The last file of the pipeline's output step. After the drive's own chapter, each stage that has a
chapter gives it from its summary and the files it wrote; a stage that was skipped gets its title
and why; a stage that did not run is named in the lead.
"""

from __future__ import annotations

from pathlib import Path

from .drive import drive_section
from .html import Section, render
from .route import route_section


def stage_folder(out_dir: Path, stage) -> Path:
    """Where ``stage`` wrote its files in ``out_dir`` (see `outputs.OutputOptions.flat`)."""
    return out_dir / stage.folder if stage.folder and (out_dir / stage.folder).is_dir() else out_dir


def build_report(signals, summary: dict, out_dir, stages, title: str = "haulprofile report", dem_dir=None,
                 private: bool = False) -> str:
    """The page: the drive's and the route's chapters, then each stage's; ``dem_dir`` gives the
    route its hillshade, ``private`` leaves the map out."""
    out_dir = Path(out_dir)
    sections: list[Section] = [drive_section(signals, summary), route_section(signals, summary, out_dir, dem_dir, private)]
    missing = []
    skipped = summary.get("skipped", {})
    for stage in stages:
        if stage.chapter is None:
            continue
        if stage.key in summary:
            sections.append(stage.chapter(summary[stage.key], stage_folder(out_dir, stage)))
        elif stage.name in skipped:
            section = Section(stage.title or stage.name)
            section.notes.append(f"Not run: {skipped[stage.name]}.")
            sections.append(section)
        else:
            missing.append(stage.key)
    lead = (f"{len(summary.get('ingest', {}).get('inputs', [])) or 'the'} input(s), "
            f"{summary.get('distance_km', 0):.1f} km in {summary.get('duration_s', 0) / 60:.0f} min.")
    if missing:
        lead += f" Not in this report (stage not run or lacking inputs): {', '.join(missing)}."
    return render(title, lead, sections)


def write_report(signals, summary: dict, directory, vehicle, stages, dem_dir=None, private: bool = False) -> str:
    """``report.html`` from the summary and the figures already written into ``directory``;
    returns its name."""
    title = "haulprofile report" + (f" — {vehicle.name}" if vehicle is not None else "")
    path = Path(directory) / "report.html"
    path.write_text(build_report(signals, summary, directory, stages, title=title, dem_dir=dem_dir, private=private),
                    encoding="utf-8")
    return path.name
