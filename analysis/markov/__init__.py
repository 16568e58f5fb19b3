"""Representative driving cycles from sparse 2D Markov chains (paper §2.3, docs/cycles.md)."""

from .chain import Chain, build_chain
from .classes import ClassWidths
from .counting import TransitionCounts, count_transitions, resample_1hz
from .criteria import Criteria, evaluate
from .export import cycle_to_vdri, write_cycle
from .generate import Candidates, generate
from .select import Selection, select_cycle
from .stage import CycleOptions, CycleResult, cycle_stage

__all__ = ["Candidates", "Chain", "ClassWidths", "Criteria", "CycleOptions", "CycleResult", "Selection",
           "TransitionCounts", "build_chain", "count_transitions", "cycle_stage", "cycle_to_vdri", "evaluate",
           "generate", "resample_1hz", "select_cycle", "write_cycle"]
