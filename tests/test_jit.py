"""The stepping loop is compiled without numba's runtime (module jit): what that allows."""

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from biped_constraint_env.jit import njit_alloc, njit_noalloc


@njit_noalloc
def _fill(out, x):
    for i in range(out.shape[0]):
        out[i] = x
    return out.shape[0]


@njit_noalloc
def _allocates(n):
    return np.zeros(n)


@njit_alloc
def _allocates_stated(n):
    return np.zeros(n).sum()


@njit_noalloc
def _calls_allocating(n):
    return _allocates_stated(n)


@njit(cache=True)
def _allocates_unstated(n):
    return np.zeros(n).sum()


@njit_noalloc
def _calls_unstated(n):
    return _allocates_unstated(n)


def test_noalloc_reads_and_writes_given_arrays():
    out = np.zeros(4)
    assert _fill(out, 2.5) == 4
    assert np.array_equal(out, np.full(4, 2.5))


def test_noalloc_refuses_to_allocate():
    with pytest.raises(TypingError):
        _allocates(3)


def test_allocating_callee_states_its_runtime():
    assert _calls_allocating(3) == 0.0


def test_unstated_callee_inherits_no_runtime():
    """Why njit_alloc exists: a plain njit callee inherits the caller's missing runtime."""
    with pytest.raises(TypingError):
        _calls_unstated(3)


def test_runtime_free_functions_call_only_stated_ones():
    """Every package function that a ``njit_noalloc`` function calls states its own runtime.

    A plain ``njit`` callee would be compiled without the runtime in that context (numba passes
    the flag on), so whether it works would depend on which caller compiled it first.
    """
    import ast
    from pathlib import Path

    import biped_constraint_env

    decorators, calls = {}, {}
    for path in Path(biped_constraint_env.__file__).parent.glob("*.py"):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef):
                decorators[node.name] = {ast.unparse(d) for d in node.decorator_list}
                calls[node.name] = {
                    c.func.id
                    for c in ast.walk(node)
                    if isinstance(c, ast.Call) and isinstance(c.func, ast.Name)
                }
    stated = {"njit_noalloc", "njit_alloc"}
    runtime_free = [f for f, d in decorators.items() if "njit_noalloc" in d]
    assert len(runtime_free) > 30  # the stepping loop
    unstated = [
        (f, c)
        for f in runtime_free
        for c in calls[f]
        if c in decorators and not decorators[c] & stated
    ]
    assert unstated == []
