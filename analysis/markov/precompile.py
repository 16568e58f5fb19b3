"""Compile the pool's kernel in a second process while the selection compiles its refinement.

On the first run after an install numba compiles two kernels for a refined selection, one after
the other: `generate.batch` for the pool's walks (a third of the compile time), then
`refine.refine_walk`. One process compiles one kernel at a time (numba's compiler lock; a thread
beside it gained nothing, docs/cycles.md), so the second core idles. Where ``batch`` has no valid
entry in numba's cache, `start` runs `compile_batch` in a second process: it compiles ``batch`` on a
small drive with the argument types of the pool and leaves it in the cache, while the selection
compiles ``refine_walk`` first (`converge.select_refined`); `wait`, before the pool, lets the
selection load ``batch`` from the cache instead of compiling it again. The kernels are the same
either way; a child that fails or cannot write the cache costs only the wait for it.
"""

from __future__ import annotations

import subprocess
import sys


def needed() -> bool:
    """True when numba's cache holds no valid compiled ``batch`` for these sources (a fresh
    install, or its source changed). False where the cache cannot be told (another numba)."""
    from .generate import batch

    try:
        return not batch._cache._cache_file._load_index()
    except (AttributeError, OSError):
        return False


def start() -> subprocess.Popen | None:
    """This module's compile in a second process, if `needed` (at normal priority: the selection
    waits for it)."""
    if not needed():
        return None
    try:
        return subprocess.Popen([sys.executable, "-c", f"import {__name__} as m; m.compile_batch()"],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except OSError:
        return None


def wait(child: subprocess.Popen | None) -> None:
    """Until the second process has left the kernel in the cache (or failed)."""
    if child is not None:
        child.wait()


def compile_batch() -> None:
    """Draw one walk as the pool does on the chain of a four-minute drive: numba compiles and
    caches ``batch`` for the pool's argument types."""
    import numpy as np

    from .chain import build_chain
    from .counting import count_transitions
    from .generate import run_batch, walk_ending

    time_s = np.arange(0.0, 240.0)
    signals = {"time_s": time_s, "speed_mps": np.clip(12.0 * np.sin(np.pi * time_s / 120.0), 0.0, None),
               "gradient_pct": 2.0 * np.sin(time_s / 30.0), "mass_kg": np.full(time_s.size, 14000.0)}
    chain = build_chain(count_transitions(signals))
    run_batch(chain, 60.0, 1, 0, 0, False, ending=walk_ending(chain, 60.0, True))
