"""The kernels compiled in a second process land in numba's cache, where the selection loads them
instead of compiling them again (`markov.precompile`)."""

import json
import os
import signal
import subprocess
import sys
import time

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
child = precompile.start(chain, counts, ending, 600.0, False, fork=sys.argv[1] == "fork")
refine(chain, counts, np.full(2, chain.start_state[0]), None, 0, 0, 0, ending=ending)
precompile.wait(child)
print(json.dumps({"needed": needed, "started": child is not None, "exit": child and child.returncode,
                  "lines": child and child.lines, "after_child": precompile.needed(), "compiled": compiled}))
"""
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
