"""How the cycle kernels are compiled: one set of numba options for all of them.

* ``cache``: compiled once per install, loaded from disk afterwards.
* ``no_cfunc_wrapper``: numba compiles, beside each kernel and its Python entry, a C-callable
  wrapper for passing it as a first-class function; no kernel is used that way. Without them and
  with the one set of options below, a first run compiles 5–7 % less (issue 29, docs/cycles.md).
* ``nogil`` on every kernel, not only on those the threads of `converge` call: numba compiles the
  helpers behind ``np.empty``, ``min`` and ``max`` once per set of options, so one set compiles
  them once. A kernel holds no Python object, so releasing the GIL changes nothing else.

A kernel called from one place only, in its own file, is an `inlined_kernel`: numba types and
lowers it inside its caller, so it has no compiled library of its own, which LLVM would optimise
and translate to machine code once for it and once more inside every caller (6 % of the first run's
compile time for the six of them). Called from Python (the tests), it compiles on its own as any
kernel. In its own file only: numba's cache checks only the file of the kernel it loads.

A kernel the cycle code calls only from other kernels is a `helper`: it is compiled without the
Python entry (the code that converts Python arguments and results, which a kernel with many array
arguments spends as much code on as on its work), which numba would otherwise compile and link
into every caller's library as well (12 % of the first run's compile time for the refinement). A
helper called from Python (the tests, a kernel's ``py_func``) runs a twin of it compiled with the
entry on first use, cached under a name of its own: numba's cache keys an entry on the function's
name, signature and source, not on its options, so the twin must not share the helper's entries.
`HelperDispatcher.await_before_compile` lets a compile wait until a second process has left the
helper in the cache (`precompile`).
"""

import types

import numba
from numba.core import config
from numba.core.registry import CPUDispatcher

OPTIONS = dict(nogil=True, no_cfunc_wrapper=True)

kernel = numba.njit(cache=True, **OPTIONS)
inlined_kernel = numba.njit(cache=True, inline="always", **OPTIONS)


class HelperDispatcher(CPUDispatcher):
    """numba's dispatcher for a `helper`: kernels call its entry-less compile, Python its twin."""

    _twin = None
    _awaited = None

    def __call__(self, *args, **kwargs):
        if self._twin is None:
            function = self.py_func
            twin = types.FunctionType(function.__code__, function.__globals__, function.__name__,
                                      function.__defaults__, function.__closure__)
            twin.__qualname__ = f"{function.__qualname__}.python_entry"
            self._twin = numba.njit(cache=True, **OPTIONS)(twin)
        return self._twin(*args, **kwargs)

    def await_before_compile(self, until) -> None:
        """Call ``until()`` (once) before this helper's next compile or load: numba then finds what
        another process has meanwhile left in the cache instead of compiling it here too."""
        self._awaited = until

    def compile(self, sig):
        until, self._awaited = self._awaited, None
        if until is not None:
            until()
        return super().compile(sig)


def helper(function):
    """``function`` as a kernel without a Python entry (see above), cached as every kernel."""
    if config.DISABLE_JIT:
        return function
    dispatcher = HelperDispatcher(py_func=function, locals={}, targetoptions=dict(no_cpython_wrapper=True, **OPTIONS))
    dispatcher.enable_caching()
    return dispatcher
