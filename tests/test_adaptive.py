"""Error-controlled RK4_LIMEX (``integrator="rk4_limex_adaptive"``): tolerance convergence,
stability beyond the explicit limits, reproducibility from a state, and its options."""

import numpy as np
import pytest
from conftest import STANCE_POSTURE
from test_simulator import DT, _sliding_heel_run, table2_periods

from biped_constraint_env.hybrid import W_CNT, nb_make_work
from biped_constraint_env.simulator import (
    ADAPTIVE_OPTIONS,
    DEFAULT_OPTIONS,
    FS_H,
    MAX_EVENTS,
    SimArrays,
    SimOptions,
    SimState,
    advance,
    nb_advance_w,
    nb_make_scratch,
    step,
)

REFERENCE = SimOptions(integrator="rk4", substeps=400)
"""The accuracy study's reference: fixed RK4, 0.05 ms steps, located events."""


@pytest.fixture(scope="module")
def sliding_reference(params):
    return _sliding_heel_run(params, REFERENCE)


def _evaluations(params, options, T=0.3):
    """Constrained evaluations over the sliding-heel scene (from the solver's counter)."""
    from benchmarks.accuracy import scene_b_start

    chs, scs = params.packed
    iopt, fopt, a, b = options.packed
    q, qd = scene_b_start(params), np.zeros(6)
    ist, fst = np.array([2, 0, 0, 0], np.int64), np.zeros(3)
    W, S = nb_make_work(), nb_make_scratch()
    ev, forces = np.zeros((MAX_EVENTS, 5)), np.zeros(5)
    for _ in range(int(round(T / DT))):
        nb_advance_w(chs, scs, q, qd, ist, fst, np.zeros((4, 5)), DT, iopt, fopt, a, b, ev,
                     forces, W, S)  # fmt: skip
    return W[W_CNT][0]


def test_error_falls_with_the_tolerance(params, sliding_reference):
    """Through a heel strike, a sliding and nearly sticking heel and a flat-foot impact: the
    error falls with the tolerance (two decades of tolerance, more than one decade of error),
    the work grows, and the default meets the accuracy rule with fewer evaluations than the
    fixed-step default (RK4_LIMEX x 8 per 20 ms)."""
    ref, sw_ref = sliding_reference
    errs, evals = [], []
    for tol in (1e-4, 1e-6):
        got, sw = _sliding_heel_run(params, ADAPTIVE_OPTIONS.replace(step_tol=tol, strict=False))
        assert len(sw) == len(sw_ref) == 2
        errs.append(max(np.abs(got - ref).max(), np.abs(sw - sw_ref).max()))
        evals.append(_evaluations(params, ADAPTIVE_OPTIONS.replace(step_tol=tol)))
    assert errs[1] < 0.1 * errs[0] and evals[1] > evals[0]
    got, sw = _sliding_heel_run(params, ADAPTIVE_OPTIONS.replace(strict=False))
    assert np.abs(got - ref).max() <= 1e-3 and np.abs(sw - sw_ref).max() <= 1e-3
    assert _evaluations(params, ADAPTIVE_OPTIONS) < 0.5 * _evaluations(params, DEFAULT_OPTIONS)


def test_accurate_with_steps_beyond_the_explicit_stability_limit(params, sliding_reference):
    """Longest step 20 ms (one per period): fixed RK4 there is unstable in the joint damping
    (limit ~11 ms) and wrong on the sticking heel (test_simulator); the controller keeps the
    error-controlled method stable and within the accuracy rule."""
    ref, sw_ref = sliding_reference
    got, sw = _sliding_heel_run(params, ADAPTIVE_OPTIONS.replace(substeps=1, strict=False))
    assert len(sw) == len(sw_ref) == 2
    assert np.abs(got - ref).max() <= 1e-3 and np.abs(sw - sw_ref).max() <= 1e-3
    st = table2_periods(params, ADAPTIVE_OPTIONS.replace(substeps=1))
    assert np.all(np.isfinite(st.qd)) and np.abs(st.qd).max() < 1e3


def test_the_next_step_is_part_of_the_state(params):
    """A run continued from a SimState takes the same steps as one never interrupted: the
    controller's next step travels in ``next_step_s`` (batched arrays and ``step`` alike)."""
    from benchmarks.accuracy import scene_b_start

    st0 = SimState(0.0, 2, 0, scene_b_start(params), np.zeros(6))
    arrays = SimArrays(1)
    arrays.set(0, st0)
    tau = np.zeros((1, 4, 5))
    st = st0
    mid = None
    for k in range(15):
        advance(params, arrays, tau, DT, ADAPTIVE_OPTIONS)
        st = step(params, st, tau[0], DT, ADAPTIVE_OPTIONS).state
        batched = arrays.get(0)
        np.testing.assert_array_equal(batched.q, st.q)
        np.testing.assert_array_equal(batched.qd, st.qd)
        assert batched.next_step_s == st.next_step_s == arrays.fst[0, FS_H]
        assert 0.0 < st.next_step_s <= DT / ADAPTIVE_OPTIONS.substeps
        if k == 3:
            mid = st  # just after the heel strike: the controller is taking short steps
    # forgetting the next step changes the steps taken (so it is really carried)
    assert mid.next_step_s < 0.5 * DT / ADAPTIVE_OPTIONS.substeps
    fresh = SimState(mid.t, mid.mode, mid.stance_side, mid.q, mid.qd, mid.root_y)
    a = step(params, mid, tau[0], DT, ADAPTIVE_OPTIONS).state
    b = step(params, fresh, tau[0], DT, ADAPTIVE_OPTIONS).state
    assert not np.array_equal(a.q, b.q)


@pytest.mark.parametrize("bad", [0.0, -1e-4, float("nan"), float("inf")])
def test_bad_tolerance_and_next_step_raise(bad):
    with pytest.raises(ValueError, match="step_tol"):
        SimOptions(step_tol=bad)
    if bad != 0.0:
        with pytest.raises(ValueError, match="next_step_s"):
            SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6), next_step_s=bad)
