"""The ``cycle`` stage of ``analyze run``: count, generate, select, write the cycle.

Options (``ctx.options["cycle"]``): ``duration_s`` (1800), ``widths`` (`ClassWidths` or its keys),
``selection`` ("refined", the default, or "paper": the paper's Monte Carlo), ``n_candidates``
(100 000 for "paper"; the pool of "refined" is `converge.POOL`), ``n_cycles`` (1; more are written
to ``cycles/``), ``n_moves`` (refinement moves per walk), ``seed`` (0), ``update_counts`` (False).
With a vehicle file (``ctx.vehicle``) the refined selection also scores the wheel loads against
the measured drive's (`load_criteria`).
"""

from __future__ import annotations

import numpy as np

from .. import signals as signals_table
from ..errors import UserError
from .chain import build_chain
from .classes import ClassWidths
from .converge import MOVES, POOL, select_refined
from .counting import count_transitions, resample_1hz
from .export import write_cycle
from .figure import plot_cycle, plot_scores
from .load_criteria import load_target
from .select import select_cycle

NEEDED = ["time_s", "speed_mps", "gradient_pct", "mass_kg"]
DEFAULTS = {"duration_s": 1800.0, "selection": "refined", "n_candidates": None, "n_cycles": 1, "n_moves": MOVES,
            "seed": 0, "update_counts": False}
SELECTIONS = ("refined", "paper")


def _select(ctx, options, counts):
    """The selections, best first."""
    method = options["selection"]
    if method not in SELECTIONS:
        raise UserError(f"cycle selection must be one of {', '.join(SELECTIONS)}, got {method!r}")
    n_cycles = int(options["n_cycles"])
    if n_cycles < 1:
        raise UserError(f"number of cycles must be at least 1, got {n_cycles}")
    if method == "paper":
        if n_cycles > 1:
            raise UserError("several cycles need the refined selection (the paper's selection keeps one)")
        return [select_cycle(counts, options["duration_s"], int(options["n_candidates"] or 100_000),
                             int(options["seed"]), bool(options["update_counts"]))]
    chain = build_chain(counts)
    target = None
    if ctx.vehicle is not None:
        target = load_target(ctx.signals, ctx.vehicle, chain)
    else:
        ctx.say("cycle: no vehicle file, so the wheel loads are not part of the score (give --vehicle)")
    return select_refined(counts, options["duration_s"], int(options["seed"]), chain, target, ctx.vehicle,
                          n_cycles, int(options["n_candidates"] or POOL), n_moves=int(options["n_moves"]),
                          update_counts=bool(options["update_counts"]))


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
    selections = _select(ctx, options, counts)
    selection = selections[0]
    paths = write_cycle(selection.cycle, ctx.out_dir)
    paths["figure"] = plot_cycle(selection.cycle, measured, ctx.out_dir / "cycle.png",
                                 selection.criteria.statement())
    paths["scores"] = plot_scores(selections, ctx.out_dir / "cycle-scores.png")
    summary = {**selection.as_dict(), "duration_s": float(options["duration_s"]),
               "class_widths": widths.as_dict(), "update_counts": bool(options["update_counts"]),
               "samples_1hz": counts.n_samples, "transitions_dropped": counts.n_dropped,
               "loops_closed": counts.n_closed, "files": {kind: path.name for kind, path in paths.items()}}
    if len(selections) > 1:
        cycles_dir = ctx.out_dir / "cycles"
        summary["cycle_set"] = {"n_cycles": len(selections), "spread": _spread(selections),
                                "cycles": [{"file": f"cycles/cycle-{i + 1}.csv", "score": s.criteria.score,
                                            "valid": s.criteria.valid, "objective": s.objective,
                                            "loads_within_allowance": s.loads_within_allowance}
                                           for i, s in enumerate(selections)]}
        for i, s in enumerate(selections):
            write_cycle(s.cycle, cycles_dir, stem=f"cycle-{i + 1}")
    ctx.summary["cycle"] = summary
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
    ctx.say(f"cycle: {selection.criteria.statement()} ({how}){loads}; wrote {', '.join(p.name for p in paths.values())}")
    if len(selections) > 1:
        spread = summary["cycle_set"]["spread"]["score"]
        ctx.say(f"cycle: {len(selections)} cycles in cycles/, score {spread['min']:.3f} … {spread['max']:.3f}")
