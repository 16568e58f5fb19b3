"""The ``cycle`` stage of ``analyze run``: count, generate, select, write the cycle.

Options (``ctx.options["cycle"]``): ``duration_s`` (1800), ``widths`` (`ClassWidths` or its keys),
``n_candidates`` (100 000), ``seed`` (0), ``update_counts`` (False).
"""

from __future__ import annotations

from .. import signals as signals_table
from .classes import ClassWidths
from .counting import count_transitions, resample_1hz
from .export import write_cycle
from .figure import plot_cycle
from .select import select_cycle

NEEDED = ["time_s", "speed_mps", "gradient_pct", "mass_kg"]
DEFAULTS = {"duration_s": 1800.0, "n_candidates": 100_000, "seed": 0, "update_counts": False}


def stage(ctx) -> None:
    missing = signals_table.missing_for(ctx.signals, NEEDED)
    if missing:
        ctx.say(f"cycle: skipped, the signals have no {', '.join(missing)} "
                f"(the gradient and mass stages provide them)")
        return
    options = {**DEFAULTS, **ctx.options.get("cycle", {})}
    widths = options.get("widths") or ClassWidths()
    if isinstance(widths, dict):
        widths = ClassWidths(**widths)
    measured = resample_1hz(ctx.signals)
    counts = count_transitions(measured, widths)
    selection = select_cycle(counts, options["duration_s"], int(options["n_candidates"]), int(options["seed"]),
                             bool(options["update_counts"]))
    paths = write_cycle(selection.cycle, ctx.out_dir)
    paths["figure"] = plot_cycle(selection.cycle, measured, ctx.out_dir / "cycle.png",
                                 selection.criteria.statement())
    ctx.summary["cycle"] = {**selection.as_dict(), "duration_s": float(options["duration_s"]),
                            "class_widths": widths.as_dict(), "update_counts": bool(options["update_counts"]),
                            "samples_1hz": counts.n_samples, "transitions_dropped": counts.n_dropped,
                            "loops_closed": counts.n_closed,
                            "files": {kind: path.name for kind, path in paths.items()}}
    left_out = selection.chain.transitions_left_out / max(int(counts.count.sum()), 1)
    if left_out > 0.1:
        ctx.say(f"cycle: {left_out:.0%} of the measured transitions lead only to the end of a log or a stop "
                f"never left, and are not drawn (docs/cycles.md, pruning)")
    ctx.say(f"cycle: {selection.criteria.statement()} (candidate {selection.index} of {selection.n_candidates}, "
            f"{selection.n_valid} valid); wrote {', '.join(p.name for p in paths.values())}")
