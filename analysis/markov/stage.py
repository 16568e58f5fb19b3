"""The cycle stage: count the measured transitions, generate candidates, select the cycle(s) (in
memory, `CycleResult`); `write_cycle_files` is its part of the output step (``cycle.csv``,
``cycle.parquet``, ``cycle.vdri``, ``cycle.png``, ``cycle-scores.png`` and, for a cycle set,
``cycles/cycle-1..N``), `cycle_chapter` its report chapter."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .. import signals as signals_table
from ..errors import UserError
from ..stage import Stage
from ..vehicle import Vehicle
from .chain import Chain, build_chain
from .chapter import TITLE, cycle_chapter
from .classes import ClassWidths
from .converge import MOVES, POOL, Progress, select_refined
from .counting import NEEDED, TransitionCounts, count_transitions, resample_1hz
from .export import write_cycle
from .figure import plot_cycle, plot_scores
from .load_criteria import LoadTarget, load_target
from .select import Selection, select_cycle

SELECTIONS = ("refined", "paper")
PAPER_CANDIDATES = 100_000
CYCLES_DIR = "cycles"


@dataclass(frozen=True)
class CycleOptions:
    """Options of the cycle stage."""

    duration_s: float = 1800.0
    """Length of the generated cycle [s]."""
    widths: ClassWidths = field(default_factory=ClassWidths)
    """Class widths of the chain: speed [km/h], gradient [%], mass [kg]."""
    selection: str = "refined"
    """"refined" (the best Monte Carlo walks improved towards the criteria and, with a vehicle, the
    wheel loads; `converge`) or "paper" (the paper's Monte Carlo, best of ``n_candidates``)."""
    n_candidates: int | None = None
    """Monte Carlo candidates: scored by "paper" (None: 100 000), the pool of "refined" (None:
    `converge.POOL`)."""
    n_cycles: int = 1
    """Representative cycles selected (a cycle set, written to ``cycles/``; "refined" only)."""
    n_moves: int = MOVES
    """Refinement moves per walk ("refined")."""
    seed: int = 0
    update_counts: bool = False
    """Draw without replacement from the measured transitions (the paper's matrix update)."""


@dataclass
class CycleResult:
    """The selected cycle(s) and what they were selected from."""

    selection: Selection
    """The chosen 1 Hz cycle (``selection.cycle``: time_s, speed_mps, accel_mps2, gradient_pct,
    mass_kg, distance_m), its criteria and the candidate set's scores."""
    counts: TransitionCounts
    measured_1hz: pd.DataFrame
    """The measured drive at 1 Hz, as counted (for the figure's distributions)."""
    selections: list[Selection] = field(default_factory=list)
    """Every selected cycle, best first (``selections[0]`` is ``selection``); more than one is a
    cycle set."""
    options: CycleOptions = field(default_factory=CycleOptions)
    """The options it was selected with."""

    @property
    def frame(self) -> pd.DataFrame:
        return self.selection.cycle

    def summary(self) -> dict:
        """The chosen cycle's criteria and score, the chain's classes and counts, a cycle set's spread."""
        selection, counts, options = self.selection, self.counts, self.options
        summary = {**selection.as_dict(), "duration_s": float(options.duration_s),
                   "class_widths": options.widths.as_dict(), "update_counts": bool(options.update_counts),
                   "samples_1hz": counts.n_samples, "transitions_dropped": counts.n_dropped,
                   "loops_closed": counts.n_closed}
        if len(self.selections) > 1:
            summary["cycle_set"] = {"n_cycles": len(self.selections), "spread": _spread(self.selections),
                                    "cycles": [{"file": f"{CYCLES_DIR}/cycle-{i + 1}.csv", "score": s.criteria.score,
                                                "valid": s.criteria.valid, "objective": s.objective,
                                                "loads_within_allowance": s.loads_within_allowance}
                                               for i, s in enumerate(self.selections)]}
        return summary

    def problem(self) -> str | None:
        if self.selection.criteria.valid:
            return None
        return (f"no valid cycle: {self.selection.criteria.statement()} (try a larger cycle.n_candidates or a "
                f"longer cycle.duration_s)")


MOVING_MPS = 0.5
"""A drive whose wheel speed never exceeds this [m/s] stood still: no cycle, said so."""


def select(options: CycleOptions, counts: TransitionCounts, chain: Chain | None = None,
           target: LoadTarget | None = None, vehicle: Vehicle | None = None,
           progress: Progress | None = None) -> list[Selection]:
    """The selections of ``options.selection``, best first: the refined one (`converge`, with the
    load criteria of ``target`` and ``vehicle`` when given) or the paper's. The one selection code
    of `analyze run`'s cycle stage and of the fleet's groups; ``progress`` hears how far it is."""
    method = options.selection
    if method not in SELECTIONS:
        raise UserError(f"cycle selection must be one of {', '.join(SELECTIONS)}, got {method!r}")
    n_cycles = int(options.n_cycles)
    if n_cycles < 1:
        raise UserError(f"number of cycles must be at least 1, got {n_cycles}")
    if options.n_candidates is not None and int(options.n_candidates) < 1:
        raise UserError(f"number of candidates must be at least 1, got {options.n_candidates}")
    if method == "paper" and n_cycles > 1:
        raise UserError("several cycles need the refined selection (the paper's selection keeps one)")

    def selections(end_at_stop: bool) -> list[Selection]:
        if method == "paper":
            return [select_cycle(counts, options.duration_s, int(options.n_candidates or PAPER_CANDIDATES),
                                 int(options.seed), bool(options.update_counts), chain, end_at_stop=end_at_stop,
                                 progress=progress)]
        return select_refined(counts, options.duration_s, int(options.seed), chain, target, vehicle,
                              n_cycles, int(options.n_candidates or POOL), n_moves=int(options.n_moves),
                              update_counts=bool(options.update_counts), end_at_stop=end_at_stop,
                              progress=progress)

    chosen = selections(end_at_stop=True)
    if not np.any(chosen[0].cycle["speed_mps"].to_numpy() > 0):
        # a drive whose only way from its stops to its end runs through the final parking (allowed
        # to a walk only in its ending) leaves no walk that moves and still ends at a stop: such a
        # cycle ends where it ends rather than standing still throughout
        chosen = selections(end_at_stop=False)
    return chosen


PROGRESS_EVERY_S = 2.0
"""Least time between two progress lines of the cycle search [s]."""
_PROGRESS_LABELS = {"pool": ("pool walks", "score"), "candidates": ("candidates", "score"),
                    "refined": ("walks refined", "objective")}


def progress_line(say, every_s: float | None = None) -> Progress:
    """A `converge.Progress` that says "cycle: 8 000 / 20 000 pool walks, best score 0.351" at
    most every ``every_s`` seconds (None: `PROGRESS_EVERY_S`)."""
    every_s = PROGRESS_EVERY_S if every_s is None else every_s
    last = [time.monotonic()]

    def progress(what: str, done: int, total: int, best: float) -> None:
        now = time.monotonic()
        if now - last[0] < every_s:
            return
        last[0] = now
        label, metric = _PROGRESS_LABELS.get(what, (what, "score"))
        count = lambda x: f"{x:,}".replace(",", " ")
        say(f"cycle: {count(done)} / {count(total)} {label}, best {metric} {best:.3f}")

    return progress


def _select(ctx, options: CycleOptions, counts) -> list[Selection]:
    """The selections of the run, best first, with the load criteria of the measured drive when
    the run has a vehicle."""
    chain = build_chain(counts) if options.selection == "refined" else None
    target = None
    if chain is not None and ctx.vehicle is not None:
        target = load_target(ctx.signals, ctx.vehicle, chain)
    elif chain is not None:
        ctx.say("cycle: no vehicle file, so the wheel loads are not part of the score (give vehicle_file)")
    return select(options, counts, chain, target, ctx.vehicle, progress_line(ctx.say))


def _spread(selections) -> dict:
    """Per criterion the smallest and largest deviation over the cycle set, and the scores."""
    result = {"score": {"min": min(s.criteria.score for s in selections),
                        "median": float(np.median([s.criteria.score for s in selections])),
                        "max": max(s.criteria.score for s in selections)},
              "all_valid": all(s.criteria.valid for s in selections), "criteria": {}}
    for name in selections[0].criteria.as_dict()["criteria"]:
        values = [s.criteria.as_dict()["criteria"][name]["deviation"] for s in selections]
        result["criteria"][name] = {"min": min(values), "max": max(values)}
    if selections[0].load_criteria is not None:
        for name in selections[0].load_criteria:
            values = [s.load_criteria[name]["deviation"] for s in selections]
            result["criteria"][name] = {"min": min(values), "max": max(values)}
    return result


def cycle_stage(ctx) -> CycleResult | None:
    """Select a representative cycle (or a set of them) of the measured drive.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``signals`` (time_s [s], speed_mps [m/s], gradient_pct [%], mass_kg [kg]),
        ``options.cycle`` (`CycleOptions`) and, for the load criteria of the refined selection,
        ``vehicle``.

    References
    ----------
    Paper §2.3: the 2D Markov chain of speed and combined gradient-and-mass classes, Monte Carlo
    candidates scored by equation (15).
    """
    missing = signals_table.missing_for(ctx.signals, NEEDED)
    if missing:
        ctx.skip("cycle", f"the signals have no {', '.join(missing)} (the gradient and mass stages provide them)")
        return None
    speed = ctx.signals["speed_mps"].to_numpy(float)
    if not np.nanmax(speed, initial=0.0) > MOVING_MPS:
        ctx.skip("cycle", f"the truck stands still throughout (wheel speed never above {MOVING_MPS:g} m/s): there "
                          f"is no driving to make a cycle of")
        return None
    options: CycleOptions = ctx.options.cycle
    measured = resample_1hz(ctx.signals)
    counts = count_transitions(measured, options.widths)
    selections = _select(ctx, options, counts)
    selection = selections[0]
    result = CycleResult(selection, counts, measured, selections, options)
    left_out = selection.chain.transitions_left_out / max(int(counts.count.sum()), 1)
    if left_out > 0.1:
        ctx.say(f"cycle: {left_out:.0%} of the measured transitions lead only to the end of a log or a stop "
                f"never left, and are not drawn (docs/cycles.md, pruning)")
    how = (f"candidate {selection.index} of {selection.n_candidates}, {selection.n_valid} valid"
           if selection.method == "paper" else
           f"refined from candidate {selection.index} of a pool of {selection.n_candidates} "
           f"(S {selection.start_score:.3f}), {len(selection.trace)} moves")
    loads = ""
    if selection.load_criteria is not None:
        loads = "; loads " + ("within" if selection.loads_within_allowance else "NOT all within") + " allowance"
    ctx.say(f"cycle: {selection.criteria.statement()} ({how}){loads}")
    if len(selections) > 1:
        spread = _spread(selections)["score"]
        ctx.say(f"cycle: {len(selections)} cycles in {CYCLES_DIR}/, score {spread['min']:.3f} … {spread['max']:.3f}")
    return result


def write_cycle_files(result: CycleResult, directory: Path, figures: bool = True) -> dict[str, str]:
    """The cycle as CSV, Parquet and VECTO ``.vdri``, a cycle set's cycles in ``cycles/`` and (with
    ``figures``) the cycle's figure and the score distribution; returns kind → file or folder name."""
    paths = write_cycle(result.frame, directory)
    if figures:
        paths["figure"] = plot_cycle(result.frame, result.measured_1hz, directory / "cycle.png",
                                     result.selection.criteria.statement())
        paths["scores"] = plot_scores(result.selections or [result.selection], directory / "cycle-scores.png")
    if len(result.selections) > 1:
        for i, s in enumerate(result.selections):
            write_cycle(s.cycle, directory / CYCLES_DIR, stem=f"cycle-{i + 1}")
        paths["set"] = directory / CYCLES_DIR
    return {kind: path.name for kind, path in paths.items()}


STAGE = Stage("cycle", CycleOptions, cycle_stage, write=write_cycle_files,
              files=("cycle.csv", "cycle.parquet", "cycle.vdri", "cycle.fastsim.csv", "cycle.png", "cycle-scores.png",
                     CYCLES_DIR),
              chapter=cycle_chapter, title=TITLE, reads_vehicle=True, required=True)
