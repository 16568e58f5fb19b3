"""The kernels compiled in a second process land in numba's cache, where the selection loads them
instead of compiling them again (`markov.precompile`)."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from haulprofile.analysis.markov import precompile

PROBE = """
import json, sys
import numpy as np
from numba.core import event
from haulprofile.analysis.markov import precompile
from haulprofile.analysis.markov.converge import refine
from haulprofile.analysis.markov.chain import build_chain
from haulprofile.analysis.markov.counting import count_transitions
from haulprofile.analysis.markov.generate import walk_ending
compiled = []
class Listener(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__name__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Listener())
time_s = np.arange(0.0, 900.0)
signals = {"time_s": time_s, "speed_mps": np.clip(15.0 * np.sin(np.pi * time_s / 200.0), 0.0, None),
           "gradient_pct": np.sin(time_s / 50.0), "mass_kg": np.full(time_s.size, 20000.0)}
counts = count_transitions(signals)
chain = build_chain(counts)
ending = walk_ending(chain, 600.0)
needed = precompile.needed()
child = precompile.start(chain, counts, ending, 600.0, False, fork=sys.argv[1] == "fork", n_pool=POOL, seed=5)
refine(chain, counts, np.full(2, chain.start_state[0]), None, 0, 0, 0, ending=ending)
if child is not None:
    child.until(None)  # a fork not stopped draws the whole pool
drawn = precompile.wait(child)
from haulprofile.analysis.markov.generate import run_batch
same = drawn is not None and drawn.tobytes() == run_batch(chain, 600.0, POOL, 5, 0, ending=ending)[0].tobytes()
print(json.dumps({"needed": needed, "started": child is not None, "exit": child and child.returncode,
                  "lines": child and child.lines, "after_child": precompile.needed(), "compiled": compiled,
                  "drawn": None if drawn is None else len(drawn), "drawn_as_here": same}))
""".replace("POOL", "601")
AHEAD = {"_kinematic_deviation", "kinematic_objective", "path_statistics", "_rejoin", "_continue", "_next_state"}
"""The kernels the child compiles for `refine_walk`, with those they call."""
MODES = ["spawn"] + (["fork"] if hasattr(os, "fork") else [])


def _probe(cache_dir, mode):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    done = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True, env=env)
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.parametrize("mode", MODES)
def test_the_second_process_leaves_the_objective_the_moves_and_batch_in_the_cache(tmp_path, mode):
    """With an empty cache a child is started (a fork of the selection or a new interpreter): the
    refinement's compile here loads the kernels of its objective's kinematic part and of its moves,
    which the child compiled for the types it passes them, and then ``batch``; with the cache
    filled no child is started and nothing is compiled."""
    first = _probe(tmp_path, mode)
    assert first["needed"] and first["started"] and first["exit"] == 0
    assert first["lines"] == [precompile.OBJECTIVE_CACHED, precompile.MOVES_CACHED]
    assert "refine_walk" in first["compiled"] and not AHEAD & set(first["compiled"])
    assert not first["after_child"] and "batch" not in first["compiled"]
    if mode == "fork":  # not stopped, it draws every candidate, each as this process draws it
        assert first["drawn"] == 601 and first["drawn_as_here"]
    else:
        assert first["drawn"] is None
    again = _probe(tmp_path, mode)
    assert not again["needed"] and not again["started"] and again["compiled"] == []


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork here")
def test_a_forked_child_is_read_line_by_line_and_a_failed_one_ends_the_waits():
    """The parent reads the child's lines only as far as it asks (what has arrived); a child that
    fails after its first line ends every later wait and reports its exit status."""
    def compile_here(tell):
        tell("first")
        tell("second")
        raise RuntimeError("compile failed")

    child = precompile._fork(compile_here)
    child.until("first")
    assert child.lines[0] == "first" and not child.ended
    child.until("never written")
    assert child.lines == ["first", "second"] and child.ended
    precompile.wait(child)
    assert child.returncode == 1
    child.until("never written")
    assert child.lines == ["first", "second"]


@pytest.mark.parametrize("mode", MODES)
def test_a_silent_child_is_ended_and_the_selection_goes_on(mode):
    """A child that writes nothing for ``silence_s`` (a fork stuck on a lock another thread held)
    is killed; every wait for it ends, and the selection compiles the rest itself."""
    if mode == "fork":
        child = precompile._fork(lambda tell: time.sleep(3600))
    else:
        process = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(3600)"], stdout=subprocess.PIPE)
        child = precompile.Child(os.dup(process.stdout.fileno()), process.wait, process.kill)
    child.silence_s = 0.2
    child.until(precompile.MOVES_CACHED)
    assert child.stuck and child.ended and child.lines == []
    precompile.wait(child)
    assert child.returncode == -signal.SIGKILL
    if mode == "spawn":
        process.stdout.close()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork here")
def test_a_fork_told_to_stop_leaves_whole_chunks_of_the_pool_in_order():
    """The fork draws the pool's first candidates chunk by chunk; told to stop (`wait`) in its
    third chunk it finishes that chunk, draws no more, and the parent gets exactly those three."""
    chunk = precompile.POOL_CHUNK
    pool = precompile.SharedPool(10 * chunk)

    def draw(first, size):
        if first == 2 * chunk:
            os.write(write_fd, b"third\n")
            while not pool._header[0]:
                time.sleep(0.001)
        return np.arange(first, first + size, dtype=float)[:, None, None] * np.ones((1, 4, 4))

    read_fd, write_fd = os.pipe()
    child = precompile._fork(lambda tell: pool.draw(draw))
    child.pool = pool
    os.close(write_fd)
    assert os.read(read_fd, 6) == b"third\n"
    os.close(read_fd)
    drawn = precompile.wait(child)
    assert child.returncode == 0 and pool.done == 3 * chunk
    np.testing.assert_array_equal(drawn[:, 0, 0], np.arange(3 * chunk))
    assert (drawn == drawn[:, :1, :1]).all()


def test_the_pool_scores_the_same_whoever_drew_its_first_candidates():
    """`converge._pool` with the first candidates' statistics given (drawn by the fork) gives the
    scores, objectives and validity it computes drawing all of them itself, for a share that ends
    inside a batch."""
    from haulprofile.analysis.markov.chain import build_chain
    from haulprofile.analysis.markov.converge import _pool
    from haulprofile.analysis.markov.counting import count_transitions
    from haulprofile.analysis.markov.generate import run_batch, walk_ending
    from haulprofile.analysis.markov.select import BATCH

    time_s = np.arange(0.0, 900.0)
    signals = {"time_s": time_s, "speed_mps": np.clip(15.0 * np.sin(np.pi * time_s / 200.0), 0.0, None),
               "gradient_pct": np.sin(time_s / 50.0), "mass_kg": np.full(time_s.size, 20000.0)}
    counts = count_transitions(signals)
    chain = build_chain(counts)
    ending = walk_ending(chain, 600.0)
    n_pool, n_drawn = 2 * BATCH + 300, BATCH + 750
    alone = _pool(chain, counts, 600.0, n_pool, 3, False, ending, None)
    drawn = run_batch(chain, 600.0, n_drawn, 3, 0, ending=ending)[0]
    reported = []
    shared = _pool(chain, counts, 600.0, n_pool, 3, False, ending, lambda *a: reported.append(a[1]), drawn)
    for a, b in zip(alone, shared):
        assert a.tobytes() == b.tobytes()
    assert reported == sorted(reported) and reported[-1] == n_pool
