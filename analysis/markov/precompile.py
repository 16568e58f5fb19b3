"""Compile a first run's kernels in a second process while the selection compiles its refinement.

On the first run after an install numba compiles two kernels for a refined selection, one after
the other: `generate.batch` for the pool's walks, then `refine.refine_walk` with every kernel it
calls. One process compiles one kernel at a time (numba's compiler lock; a thread beside it gained
nothing, docs/cycles.md), so the second core idles. Where ``batch`` has no valid entry in numba's
cache, `start` runs `compile_ahead` in a second process. It compiles, for the argument types the
selection gives them, the kernels of the objective's kinematic part (`refine.OBJECTIVE_KERNELS`),
then those of the refinement's moves (`refine.MOVE_KERNELS`), then ``batch``, and leaves them in
the cache, writing a line after each group. Meanwhile the selection compiles ``refine_walk``
(`converge.select_refined`): where numba reaches one of these kernels it waits for the child's
line and loads it, and `wait`, before the pool, lets it load ``batch`` as well. The kernels are
the same either way; a child that fails or cannot write the cache costs only the waits for it.

Where the system can, the second process is a fork of this one (`os.fork`): it needs no imports
and no numba set-up of its own (about a second of CPU on a first run, docs/cycles.md), and it
compiles for the selection's own chain. Elsewhere it is a new interpreter that compiles on the
chain of a four-minute synthetic drive (`compile_in_child`), with the same types.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
from collections.abc import Callable

OBJECTIVE_CACHED = "objective"
"""The child's line once the objective's kernels are in the cache."""
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


SILENCE_S = 120.0
"""How long the selection waits for the child's next line before it takes the child for stuck
and ends it [s]. Its whole work takes 3-15 s here (docs/cycles.md); a fork can hang on a lock
another thread of the parent held when it was forked. The selection then compiles the rest itself:
the kernels are the same either way."""


class Child:
    """The second process, and how far it has come: the lines it wrote on the pipe ``fd``, read
    as they are needed; ``reap()`` waits for its end and returns its exit status, ``kill()`` ends
    it."""

    def __init__(self, fd: int, reap: Callable[[], int], kill: Callable[[], None], silence_s: float = SILENCE_S):
        self.fd = fd
        self.reap = reap
        self.kill = kill
        self.silence_s = silence_s
        self.lines: list[str] = []
        self._partial = b""
        self.ended = False
        self.stuck = False
        self.returncode: int | None = None

    def until(self, line: str | None) -> None:
        """Until the child has written ``line`` (or ended, or been silent for ``silence_s``;
        None: until it has ended)."""
        while not self.ended and (line is None or line not in self.lines):
            readable, _, _ = select.select([self.fd], [], [], self.silence_s)
            if not readable:
                self.stuck = self.ended = True
                self.kill()
                break
            data = os.read(self.fd, 4096)
            if not data:
                self.ended = True
                break
            *complete, self._partial = (self._partial + data).split(b"\n")
            self.lines += [text.decode(errors="replace").strip() for text in complete]

    def finish(self) -> None:
        """Until the child has ended; its exit status in ``returncode``."""
        if self.returncode is None:
            self.until(None)
            os.close(self.fd)
            self.returncode = self.reap()


def _prepare_compiler() -> None:
    """Set up numba's typing and lowering registries now (what a process's first compile does
    first, 0.3–0.4 s): a forked child then inherits them instead of repeating the work."""
    from numba.core.registry import cpu_target

    cpu_target.typing_context.refresh()
    cpu_target.target_context.refresh()


def _fork(compile_here: Callable[[Callable[[str], None]], None]) -> Child | None:
    """``compile_here(tell)`` in a fork of this process, ``tell(line)`` writing to the parent.
    Forked while holding numba's compiler lock, so no thread of this process is inside a compile
    (a child forked mid-compile would wait for that lock for ever)."""
    from numba.core.compiler_lock import global_compiler_lock

    read_fd, write_fd = os.pipe()
    try:
        with global_compiler_lock:
            pid = os.fork()
    except OSError:
        os.close(read_fd)
        os.close(write_fd)
        return None
    if pid == 0:  # the child: compile, tell, and end without the parent's exit handlers or errors
        status = 1
        try:
            os.close(read_fd)
            compile_here(lambda line: os.write(write_fd, f"{line}\n".encode()))
            status = 0
        finally:
            os._exit(status)
    os.close(write_fd)
    return Child(read_fd, lambda: os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]),
                 lambda: os.kill(pid, signal.SIGKILL))


def _spawn() -> Child | None:
    """`compile_in_child` in a new interpreter."""
    try:
        process = subprocess.Popen([sys.executable, "-c", f"import {__name__} as m; m.compile_in_child()"],
                                   stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    except OSError:
        return None

    def reap() -> int:
        process.stdout.close()
        return process.wait()

    return Child(os.dup(process.stdout.fileno()), reap, process.kill)


def start(chain, counts, ending, duration_s: float, update_counts: bool, fork: bool | None = None) -> Child | None:
    """The compile ahead in a second process, if `needed` (at normal priority: the selection waits
    for it), for the selection's chain, counts, ending, duration [s] and ``update_counts``; the
    refinement's compile waits for each kernel the child compiles where it needs it. ``fork``:
    a fork of this process (None: where the system has ``os.fork`` and is not macOS, whose system
    libraries are not safe to use in a fork) or a new interpreter."""
    if not needed():
        return None
    from .refine import MOVE_KERNELS, OBJECTIVE_KERNELS

    if fork is None:
        fork = hasattr(os, "fork") and sys.platform != "darwin"
    if fork:
        _prepare_compiler()
        child = _fork(lambda tell: compile_ahead(chain, counts, ending, duration_s, update_counts, tell))
    else:
        child = _spawn()
    if child is None:
        return None
    for kernels, line in ((OBJECTIVE_KERNELS, OBJECTIVE_CACHED), (MOVE_KERNELS, MOVES_CACHED)):
        for kernel in kernels:
            kernel.await_before_compile(lambda line=line: child.until(line))
    return child


def wait(child: Child | None) -> None:
    """Until the second process has left its kernels in the cache (or failed)."""
    if child is not None:
        child.finish()


def compile_ahead(chain, counts, ending, duration_s: float, update_counts: bool,
                  tell: Callable[[str], None]) -> None:
    """The objective's kernels, the moves' kernels and ``batch``, for the types a selection with
    these arguments gives them; ``tell`` the lines `OBJECTIVE_CACHED` and `MOVES_CACHED` after the
    first two groups."""
    from .generate import run_batch
    from .refine import MOVE_KERNELS, OBJECTIVE_KERNELS, compile_moves, compile_objective

    for kernel in OBJECTIVE_KERNELS + MOVE_KERNELS:  # a fork's copy of the parent's waits
        kernel.await_before_compile(None)
    compile_objective(chain, counts)
    tell(OBJECTIVE_CACHED)
    compile_moves(chain.row_ptr, chain.dest, chain.count, chain.cum_count, ending.as_tuple())
    tell(MOVES_CACHED)
    run_batch(chain, duration_s, 1, 0, 0, update_counts, ending=ending)


def compile_in_child() -> None:
    """`compile_ahead` in a new interpreter, on the chain of a four-minute drive; its lines on
    stdout."""
    import numpy as np

    from .chain import build_chain
    from .counting import count_transitions
    from .generate import walk_ending

    time_s = np.arange(0.0, 240.0)
    signals = {"time_s": time_s, "speed_mps": np.clip(12.0 * np.sin(np.pi * time_s / 120.0), 0.0, None),
               "gradient_pct": 2.0 * np.sin(time_s / 30.0), "mass_kg": np.full(time_s.size, 14000.0)}
    counts = count_transitions(signals)
    chain = build_chain(counts)
    compile_ahead(chain, counts, walk_ending(chain, 60.0, True), 60.0, False, lambda line: print(line, flush=True))
