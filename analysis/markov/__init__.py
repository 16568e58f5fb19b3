"""Representative driving cycles from sparse 2D Markov chains (paper §2.3, docs/cycles.md)."""
from .classes import ClassWidths
from .counting import TransitionCounts, count_transitions, resample_1hz
from .chain import Chain, build_chain
from .generate import Candidates, generate
from .criteria import Criteria, evaluate
from .select import Selection, select_cycle
from .export import cycle_to_vdri, vdri_to_time_cycle, write_cycle
from .stage import stage
