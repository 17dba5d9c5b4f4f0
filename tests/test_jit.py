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
