"""Reference motions on the contact clock (biped_constraint_env.reference)."""

import numpy as np
import pytest

from biped_constraint_env import paper_biped
from biped_constraint_env.reference import REFERENCES, load_reference
from biped_constraint_env.simulator import SimState
from biped_constraint_env.starts import check_start_state


@pytest.mark.parametrize("name", REFERENCES)
def test_the_clock_restarts_at_every_model_switch(name):
    ref = load_reference(name)
    switch = np.flatnonzero(np.diff(ref.mode) != 0) + 1
    assert len(switch) >= 40  # 10 s of walking: more than ten steps
    assert np.all(ref.j[switch] == 0)
    same = np.flatnonzero(np.diff(ref.mode) == 0) + 1
    assert np.all(ref.j[same] == ref.j[same - 1] + 1)


@pytest.mark.parametrize("name", REFERENCES)
def test_lookup_gives_the_recorded_state_of_the_same_phase(name):
    ref = load_reference(name)
    for mode in (1, 2, 3, 4):
        rows = np.flatnonzero((ref.mode == mode) & (ref.step == ref.gait_step) & (ref.first == 0))
        for i in rows[:: max(len(rows) // 4, 1)]:
            want = np.concatenate([ref.q[i], ref.qd[i], ref.hip[i]])
            np.testing.assert_array_equal(ref.lookup(0, mode, ref.j[i]), want)
        last = rows[-1]
        np.testing.assert_array_equal(ref.lookup(0, mode, 10**6)[:6], ref.q[last])  # held


def test_the_rest_reference_walks_its_own_first_step():
    ref = load_reference("rest")
    assert ref.first[0] == 1 and ref.mode[0] == 1 and np.all(ref.qd[0] == 0)
    assert {m for m in (1, 2, 3, 4) if (1, m) in ref.tables} == {1, 2, 3, 4}
    assert not np.array_equal(ref.tables[(1, 1)][:5], ref.tables[(0, 1)][:5])
    mid = load_reference("midstride")
    assert not mid.first.any()


@pytest.mark.parametrize("name", REFERENCES)
def test_recorded_states_are_valid_starts(name):
    """Reference-state initialisation starts from recorded states: each is inside its model."""
    ref = load_reference(name)
    params = paper_biped()
    for i in range(0, len(ref.q), 97):
        check_start_state(params, SimState(0.0, int(ref.mode[i]), 0, ref.q[i], ref.qd[i]))


def test_unknown_reference_is_refused():
    with pytest.raises(ValueError, match="reference"):
        load_reference("backwards")
