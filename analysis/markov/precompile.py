"""Compile a first run's kernels in a second process while the selection compiles its refinement.

On the first run after an install numba compiles two kernels for a refined selection, one after
the other: `generate.batch` for the pool's walks, then `refine.refine_walk` with every kernel it
calls. One process compiles one kernel at a time (numba's compiler lock; a thread beside it gained
nothing, docs/cycles.md), so the second core idles. Where ``batch`` has no valid entry in numba's
cache, `start` runs `compile_in_child` in a second process. It first compiles the kernels of the
refinement's moves (`refine.MOVE_KERNELS`) for the argument types ``refine_walk`` gives them, then
``batch`` for the pool's, and leaves them in the cache. Meanwhile the selection compiles
``refine_walk`` (`converge.select_refined`): numba reaches the moves' kernels last, waits there
until the child has cached them and loads them, and `wait`, before the pool, lets the selection
load ``batch`` as well. The kernels are the same either way; a child that fails or cannot write
the cache costs only the waits for it.
"""

from __future__ import annotations

import subprocess
import sys

MOVES_CACHED = "moves"
"""The child's line once the moves' kernels are in the cache."""


def needed() -> bool:
    """True when numba's cache holds no valid compiled ``batch`` for these sources (a fresh
    install, or its source changed). False where the cache cannot be told (another numba)."""
    from .generate import batch

    try:
        return not batch._cache._cache_file._load_index()
    except (AttributeError, OSError):
        return False


class Child:
    """The second process, and how far it has come."""

    def __init__(self, process: subprocess.Popen):
        self.process = process
        self.lines: list[str] = []

    def until(self, line: str) -> None:
        """Until the child has written ``line`` (or ended)."""
        while line not in self.lines:
            out = self.process.stdout.readline()
            if not out:
                return
            self.lines.append(out.strip())


def start() -> Child | None:
    """This module's compile in a second process, if `needed` (at normal priority: the selection
    waits for it); the refinement's compile waits for the moves' kernels where it needs them."""
    if not needed():
        return None
    from .refine import MOVE_KERNELS

    try:
        process = subprocess.Popen([sys.executable, "-c", f"import {__name__} as m; m.compile_in_child()"],
                                   stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                   text=True)
    except OSError:
        return None
    child = Child(process)
    for kernel in MOVE_KERNELS:
        kernel.await_before_compile(lambda: child.until(MOVES_CACHED))
    return child


def wait(child: Child | None) -> None:
    """Until the second process has left its kernels in the cache (or failed)."""
    if child is not None:
        child.until(MOVES_CACHED)
        child.process.communicate()


def compile_in_child() -> None:
    """The moves' kernels and then ``batch``, on the chain of a four-minute drive; the line
    `MOVES_CACHED` on stdout between the two."""
    import numpy as np

    from .chain import build_chain
    from .counting import count_transitions
    from .generate import run_batch, walk_ending
    from .refine import compile_moves

    time_s = np.arange(0.0, 240.0)
    signals = {"time_s": time_s, "speed_mps": np.clip(12.0 * np.sin(np.pi * time_s / 120.0), 0.0, None),
               "gradient_pct": 2.0 * np.sin(time_s / 30.0), "mass_kg": np.full(time_s.size, 14000.0)}
    chain = build_chain(count_transitions(signals))
    ending = walk_ending(chain, 60.0, True)
    compile_moves(chain.row_ptr, chain.dest, chain.count, chain.cum_count, ending.as_tuple())
    print(MOVES_CACHED, flush=True)
    run_batch(chain, 60.0, 1, 0, 0, False, ending=ending)
