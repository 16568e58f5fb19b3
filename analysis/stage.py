"""What every analysis stage declares, in its own folder, so that the pipeline, the output step and
the report can loop over `pipeline.STAGES` without naming one.

A stage is one `Stage`: its name, its options dataclass, the function that runs it on the run
(`RunContext`) and returns its typed result (None when it was skipped, `RunContext.skip` saying
why), what it writes and its report chapter. The result's ``summary()`` is the one source of the
stage's numbers in ``summary.json``, the report and ``--json``; the chapter reads that summary, so
a report can be drawn again from ``summary.json`` and the files beside it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Protocol


class StageResult(Protocol):
    """A stage's typed result."""

    def summary(self) -> dict:
        """The stage's numbers, strict-JSON-able (``summary.json[<stage>]``)."""

    def problem(self) -> str | None:
        """One line when the result did not meet its criteria (``analyze`` exits 3), else None.
        Optional: a result without it is always trustworthy."""


Write = Callable[[Any, Path, bool], "list[str] | dict[str, str]"]
"""``write(result, folder, figures)``: the stage's files written into ``folder`` (created by the
caller), figures only with ``figures``; returns the names written (or kind → name)."""

Chapter = Callable[[dict, Path], Any]
"""``chapter(summary, folder)``: the stage's report `Section` from its own summary and the files
it wrote into ``folder``."""


@dataclass(frozen=True)
class Stage:
    """One step of the analysis, as its folder declares it."""

    name: str
    """The stage's name: in ``analyze --help``, ``until=``, the options, the results and the summary."""
    options: type
    """Its options dataclass (every field has a default)."""
    run: Callable[[Any], Any]
    """``run(ctx)`` → its typed result (`StageResult`), or None when skipped (``ctx.skip(...)``)."""
    write: Write | None = None
    files: tuple[str, ...] = ()
    """Every name ``write`` may create in its folder: what a full run removes when it did not write
    it this time, and what the output step checks is not an input."""
    folder: str = ""
    """The output directory's subfolder its files go to ("": the directory itself)."""
    chapter: Chapter | None = None
    title: str = ""
    """The chapter's title, also used to say why the stage did not run."""
    summary_key: str | None = None
    """Where ``summary()`` goes in ``summary.json``: the stage's name by default; "" merges it
    into the top level (the drive's own figures)."""
    reads_vehicle: bool = False
    """A change of the vehicle file reruns it (and every stage after it)."""
    reads_dem: bool = False
    """A change of the DEM tiles reruns it."""
    needs_signals: bool = True
    required: bool = False
    """A run where it was skipped is not trustworthy (``analyze`` exits 3)."""

    @property
    def key(self) -> str:
        return self.name if self.summary_key is None else self.summary_key


class Results(dict):
    """Each stage's typed result by stage name (``results.mass``); a stage that did not run, or
    was skipped, has none (``results.cycle is None``)."""

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        return self.get(name)

    def __setattr__(self, name: str, value) -> None:
        self[name] = value
