"""The cycle kernels' helpers (`markov.jit.helper`): compiled without a Python entry for kernels,
callable from Python all the same, and able to wait for another process before compiling."""

import json
import os
import subprocess
import sys

PROBE = """
import json
from numba.core import event
from haulprofile.analysis.markov.jit import helper, kernel
order = []
class Listener(event.Listener):
    def on_start(self, ev):
        order.append("compile " + ev.data["dispatcher"].py_func.__name__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Listener())

@helper
def twice(x):
    return 2 * x

@kernel
def twice_plus_one(x):
    return twice(x) + 1

twice.await_before_compile(lambda: order.append("awaited"))
from_kernel = twice_plus_one(20)
compiled = list(twice.overloads.values())  # the helper's own compile, not the twin's
has_python_entry = [c.fndesc.llvm_cpython_wrapper_name in c.library.get_llvm_str() for c in compiled]
print(json.dumps({"order": order, "from_kernel": from_kernel, "from_python": twice(20),
                  "has_python_entry": has_python_entry}))
"""


def _probe(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    done = subprocess.run([sys.executable, str(tmp_path / "probe.py")], capture_output=True, text=True, check=True,
                          env=env)
    return json.loads(done.stdout.splitlines()[-1])


def test_a_helper_compiles_without_python_entry_runs_from_python_and_awaits_once(tmp_path):
    """The helper compiles once for the kernel, without a Python entry, after the awaited call;
    Python runs its twin, compiled once more with the entry; a second process compiles nothing."""
    (tmp_path / "probe.py").write_text(PROBE)  # a file: numba caches only kernels defined in one
    out = _probe(tmp_path)
    assert out["from_kernel"] == 41 and out["from_python"] == 40
    assert out["has_python_entry"] == [False]
    compiles = [o for o in out["order"] if o == "compile twice"]
    assert out["order"].index("awaited") < out["order"].index("compile twice")
    assert out["order"].count("awaited") == 1 and len(compiles) == 2  # the helper, then its twin for Python
    again = _probe(tmp_path)
    assert again["from_kernel"] == 41 and again["from_python"] == 40 and again["order"] == []
