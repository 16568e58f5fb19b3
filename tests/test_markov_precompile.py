"""The pool's kernel compiled in a second process lands in numba's cache, where the selection
loads it instead of compiling it again (`markov.precompile`)."""

import json
import os
import subprocess
import sys

PROBE = """
import json
from numba.core import event
from haulprofile.analysis.markov import precompile
compiled = []
class Listener(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__name__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Listener())
needed = precompile.needed()
child = precompile.start()
precompile.wait(child)
after_child = precompile.needed()
precompile.compile_batch()
print(json.dumps({"needed": needed, "started": child is not None, "exit": child and child.returncode,
                  "after_child": after_child, "compiled": compiled}))
"""


def _probe(cache_dir):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True, env=env)
    return json.loads(done.stdout.splitlines()[-1])


def test_the_second_process_leaves_batch_in_the_cache(tmp_path):
    """With an empty cache a child is started and compiles ``batch`` into it: this process then
    loads the kernel; with the cache filled no child is started."""
    first = _probe(tmp_path)
    assert first["needed"] and first["started"] and first["exit"] == 0
    assert not first["after_child"] and "batch" not in first["compiled"]
    again = _probe(tmp_path)
    assert not again["needed"] and not again["started"] and "batch" not in again["compiled"]
