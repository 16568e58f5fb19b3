"""The cycle stage: count the measured transitions, generate candidates, select the cycle (in
memory, `CycleResult`); `write_cycle_files` is its part of the output step (``cycle.csv``,
``cycle.parquet``, ``cycle.vdri``, ``cycle.png``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from .. import signals as signals_table
from .classes import ClassWidths
from .counting import TransitionCounts, count_transitions, resample_1hz
from .export import write_cycle
from .figure import plot_cycle
from .select import Selection, select_cycle

NEEDED = ["time_s", "speed_mps", "gradient_pct", "mass_kg"]


@dataclass(frozen=True)
class CycleOptions:
    """Options of the cycle stage."""

    duration_s: float = 1800.0
    """Length of the generated cycle [s]."""
    widths: ClassWidths = field(default_factory=ClassWidths)
    """Class widths of the chain: speed [km/h], gradient [%], mass [kg]."""
    n_candidates: int = 100_000
    """Monte Carlo candidates scored."""
    seed: int = 0
    update_counts: bool = False
    """Draw without replacement from the measured transitions (the paper's matrix update)."""


@dataclass
class CycleResult:
    """The selected cycle and what it was selected from."""

    selection: Selection
    """The chosen 1 Hz cycle (``selection.cycle``: time_s, speed_mps, accel_mps2, gradient_pct,
    mass_kg, distance_m), its criteria and the candidate set's scores."""
    counts: TransitionCounts
    measured_1hz: pd.DataFrame
    """The measured drive at 1 Hz, as counted (for the figure's distributions)."""

    @property
    def frame(self) -> pd.DataFrame:
        return self.selection.cycle


def cycle_stage(ctx) -> None:
    """Select a representative cycle of the measured drive into ``ctx.results.cycle`` and
    ``ctx.summary["cycle"]``.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``signals`` (time_s [s], speed_mps [m/s], gradient_pct [%], mass_kg [kg]) and
        ``options.cycle`` (`CycleOptions`).

    References
    ----------
    Paper §2.3: the 2D Markov chain of speed and combined gradient-and-mass classes, Monte Carlo
    candidates scored by equation (15).
    """
    missing = signals_table.missing_for(ctx.signals, NEEDED)
    if missing:
        ctx.skip("cycle", f"the signals have no {', '.join(missing)} (the gradient and mass stages provide them)")
        return
    options: CycleOptions = ctx.options.cycle
    measured = resample_1hz(ctx.signals)
    counts = count_transitions(measured, options.widths)
    selection = select_cycle(counts, options.duration_s, int(options.n_candidates), int(options.seed),
                             bool(options.update_counts))
    ctx.results.cycle = CycleResult(selection, counts, measured)
    ctx.summary["cycle"] = {**selection.as_dict(), "duration_s": float(options.duration_s),
                            "class_widths": options.widths.as_dict(), "update_counts": bool(options.update_counts),
                            "samples_1hz": counts.n_samples, "transitions_dropped": counts.n_dropped,
                            "loops_closed": counts.n_closed}
    left_out = selection.chain.transitions_left_out / max(int(counts.count.sum()), 1)
    if left_out > 0.1:
        ctx.say(f"cycle: {left_out:.0%} of the measured transitions lead only to the end of a log or a stop "
                f"never left, and are not drawn (docs/cycles.md, pruning)")
    ctx.say(f"cycle: {selection.criteria.statement()} (candidate {selection.index} of {selection.n_candidates}, "
            f"{selection.n_valid} valid)")


def write_cycle_files(result: CycleResult, directory: Path, figures: bool = True) -> dict[str, str]:
    """The cycle as CSV, Parquet and VECTO ``.vdri`` and (with ``figures``) its figure; returns
    kind → file name."""
    paths = write_cycle(result.frame, directory)
    if figures:
        paths["figure"] = plot_cycle(result.frame, result.measured_1hz, directory / "cycle.png",
                                     result.selection.criteria.statement())
    return {kind: path.name for kind, path in paths.items()}
