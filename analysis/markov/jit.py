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
"""

import numba

kernel = numba.njit(cache=True, nogil=True, no_cfunc_wrapper=True)
inlined_kernel = numba.njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
