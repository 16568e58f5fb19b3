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

A fork finishes ``batch`` before the selection finishes ``refine_walk``; until the selection
wants its pool it then draws the pool's first candidates (`SharedPool`) instead of idling. Each
candidate is drawn from its own seed stream, so which process drew it changes no number.
"""

from __future__ import annotations

import mmap
import os
import select
import signal
import subprocess
import sys
from collections.abc import Callable

import numpy as np

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


POOL_CHUNK = 250
"""Candidates a fork draws between two looks at whether the selection wants the pool back (about
7 ms here: the longest the selection waits for it)."""


class SharedPool:
    """Pool statistics (``n_pool``, 4, 4) in memory a fork shares with its parent: the child draws
    candidates 0, 1, … in chunks of `POOL_CHUNK` until the parent says `stop`; ``done`` counts
    those whose statistics are complete (written after each chunk is)."""

    def __init__(self, n_pool: int):
        self._memory = mmap.mmap(-1, 16 + max(n_pool, 1) * 16 * 8)
        self._header = np.frombuffer(self._memory, np.int64, 2)
        self.stats = np.frombuffer(self._memory, np.float64, n_pool * 16, 16).reshape(n_pool, 4, 4)

    @property
    def done(self) -> int:
        return int(self._header[1])

    def stop(self) -> None:
        self._header[0] = 1

    def draw(self, draw_stats: Callable[[int, int], np.ndarray]) -> None:
        """In the child: ``draw_stats(first, n)`` for chunks in order, until stopped or full."""
        n_pool = self.stats.shape[0]
        while not self._header[0] and self.done < n_pool:
            first = self.done
            size = min(POOL_CHUNK, n_pool - first)
            self.stats[first:first + size] = draw_stats(first, size)
            self._header[1] = first + size

    def drawn(self) -> np.ndarray:
        """In the parent, once the child has ended: the statistics of the candidates it drew."""
        return self.stats[:self.done].copy()


class Child:
    """The second process, and how far it has come: the lines it wrote on the pipe ``fd``, read
    as they are needed; ``reap()`` waits for its end and returns its exit status, ``kill()`` ends
    it; ``pool`` the candidates it draws (a fork only)."""

    def __init__(self, fd: int, reap: Callable[[], int], kill: Callable[[], None], silence_s: float = SILENCE_S,
                 pool: SharedPool | None = None):
        self.fd = fd
        self.reap = reap
        self.kill = kill
        self.silence_s = silence_s
        self.pool = pool
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


def start(chain, counts, ending, duration_s: float, update_counts: bool, fork: bool | None = None,
          n_pool: int = 0, seed: int = 0) -> Child | None:
    """The compile ahead in a second process, if `needed` (at normal priority: the selection waits
    for it), for the selection's chain, counts, ending, duration [s] and ``update_counts``; the
    refinement's compile waits for each kernel the child compiles where it needs it. ``fork``:
    a fork of this process (None: where the system has ``os.fork`` and is not macOS, whose system
    libraries are not safe to use in a fork) or a new interpreter. A fork then draws the first of
    the ``n_pool`` candidates of ``seed`` until `wait`."""
    if not needed():
        return None
    from .refine import MOVE_KERNELS, OBJECTIVE_KERNELS

    if fork is None:
        fork = hasattr(os, "fork") and sys.platform != "darwin"
    if fork:
        _prepare_compiler()
        pool = SharedPool(n_pool) if n_pool > 0 else None
        child = _fork(lambda tell: compile_ahead(chain, counts, ending, duration_s, update_counts, tell, pool, seed))
        if child is not None:
            child.pool = pool
    else:
        child = _spawn()
    if child is None:
        return None
    for kernels, line in ((OBJECTIVE_KERNELS, OBJECTIVE_CACHED), (MOVE_KERNELS, MOVES_CACHED)):
        for kernel in kernels:
            kernel.await_before_compile(lambda line=line: child.until(line))
    return child


def wait(child: Child | None) -> np.ndarray | None:
    """Until the second process has left its kernels in the cache (or failed), after telling it to
    stop drawing the pool; the statistics of the pool's first candidates, which it drew (None if
    it drew none)."""
    if child is None:
        return None
    if child.pool is not None:
        child.pool.stop()
    child.finish()
    return child.pool.drawn() if child.pool is not None and child.pool.done else None


def compile_ahead(chain, counts, ending, duration_s: float, update_counts: bool,
                  tell: Callable[[str], None], pool: SharedPool | None = None, seed: int = 0) -> None:
    """The objective's kernels, the moves' kernels and ``batch``, for the types a selection with
    these arguments gives them; ``tell`` the lines `OBJECTIVE_CACHED` and `MOVES_CACHED` after the
    first two groups; then the first candidates of ``seed`` into ``pool``, if given."""
    from .generate import run_batch
    from .refine import MOVE_KERNELS, OBJECTIVE_KERNELS, compile_moves, compile_objective

    for kernel in OBJECTIVE_KERNELS + MOVE_KERNELS:  # a fork's copy of the parent's waits
        kernel.await_before_compile(None)
    compile_objective(chain, counts)
    tell(OBJECTIVE_CACHED)
    compile_moves(chain.row_ptr, chain.dest, chain.count, chain.cum_count, ending.as_tuple())
    tell(MOVES_CACHED)
    run_batch(chain, duration_s, 1, 0, 0, update_counts, ending=ending)
    if pool is not None:
        pool.draw(lambda first, size: run_batch(chain, duration_s, size, seed, first, update_counts, ending=ending)[0])


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
