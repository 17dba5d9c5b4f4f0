"""How the compiled core is compiled: numba's ``njit``, cached, with or without its runtime.

Most compiled functions use plain ``numba.njit(cache=True)``. The stepping loop's functions
(the forward pass, the constrained solve, the integrator step, its error estimate, event
location, the period loop) use :func:`njit_noalloc` instead: compiled without numba's runtime
(NRT), they allocate nothing and return no array, and their array arguments are borrowed, so
no reference count is touched when one calls another.

Why: those functions pass the workspace and scratch tuples (28 arrays, views of two buffers)
from call to call, and with the runtime every call atomically increments, then decrements,
the reference count of each array in them, all on the same two counters; numba's
reference-count pruning does not remove that across calls. Measured on the walking task's
recorded actions (256 environments, one thread), a period took 9.2 us per environment with
the runtime and 5.7 us without. The arithmetic is the same either way, so results are
bit-identical.

``_nrt`` is numba's own option for this (numba compiles parts of its own library with it); a
function under it that allocates, or calls one that returns a new array, fails to compile
("NRT required but not enabled"), so a mistake cannot pass silently. A function called from one
of them inherits the setting unless it states its own: the few allocating functions that the
stepping loop calls (the reset map at a switch) use :func:`njit_alloc`.
"""

from __future__ import annotations

from numba import njit


def njit_noalloc(fn):
    """``numba.njit(cache=True)`` without numba's runtime: for functions that allocate nothing.

    The function may read and write arrays it is given and call other compiled functions that
    return scalars or tuples of scalars; it may not create arrays (``np.empty``, ``.copy()``,
    array expressions) nor call a function that returns one.
    """
    return njit(cache=True, _nrt=False)(fn)


def njit_alloc(fn):
    """``numba.njit(cache=True)`` with numba's runtime stated explicitly.

    For an allocating function that a :func:`njit_noalloc` function calls, which would
    otherwise inherit the caller's setting and fail to compile.
    """
    return njit(cache=True, _nrt=True)(fn)
