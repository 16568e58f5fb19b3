"""The kernels compiled in a second process land in numba's cache, where the selection loads them
instead of compiling them again (`markov.precompile`)."""

import json
import os
import subprocess
import sys

PROBE = """
import json
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
needed = precompile.needed()
child = precompile.start()
refine(chain, counts, np.full(2, chain.start_state[0]), None, 0, 0, 0, ending=walk_ending(chain, 600.0))
precompile.wait(child)
after_child = precompile.needed()
precompile.compile_in_child()
print(json.dumps({"needed": needed, "started": child is not None, "exit": child and child.process.returncode,
                  "lines": child and child.lines, "after_child": after_child, "compiled": compiled}))
"""
MOVES = {"_rejoin", "_continue", "_next_state"}


def _probe(cache_dir):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True, env=env)
    return json.loads(done.stdout.splitlines()[-1])


def test_the_second_process_leaves_the_moves_and_batch_in_the_cache(tmp_path):
    """With an empty cache a child is started: the refinement's compile here loads the kernels of
    its moves, which the child compiled for the types it passes them, and then ``batch``; with the
    cache filled no child is started and nothing is compiled."""
    first = _probe(tmp_path)
    assert first["needed"] and first["started"] and first["exit"] == 0 and first["lines"] == ["moves"]
    assert "refine_walk" in first["compiled"] and not MOVES & set(first["compiled"])
    assert not first["after_child"] and "batch" not in first["compiled"]
    again = _probe(tmp_path)
    assert not again["needed"] and not again["started"] and again["compiled"] == []
