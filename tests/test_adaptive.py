"""Error-controlled RK4_LIMEX (``integrator="rk4_limex_adaptive"``): tolerance convergence,
stability beyond the explicit limits, reproducibility from a state, and its options."""

import numpy as np
import pytest
from conftest import STANCE_POSTURE
from test_simulator import DT, _sliding_heel_run, table2_periods

from biped_constraint_env.advance import nb_advance_w
from biped_constraint_env.hybrid import W_CNT, nb_make_work
from biped_constraint_env.simulator import (
    DEFAULT_OPTIONS,
    FIXED_STEP_OPTIONS,
    SimArrays,
    SimOptions,
    SimState,
    advance,
    step,
)
from biped_constraint_env.state import FS_H, MAX_EVENTS, N_FST
from biped_constraint_env.stepper import nb_make_scratch

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
    ist, fst = np.array([2, 0, 0, 0], np.int64), np.zeros(N_FST)
    W, S = nb_make_work(), nb_make_scratch()
    ev, forces = np.zeros((MAX_EVENTS, 5)), np.zeros(5)
    for _ in range(int(round(T / DT))):
        nb_advance_w(chs, scs, q, qd, ist, fst, np.zeros((4, 5)), DT, iopt, fopt, a, b, ev,
                     forces, W, S)  # fmt: skip
    return W[W_CNT][0]


def test_error_falls_with_the_tolerance(params, sliding_reference):
    """Through a heel strike, a sliding and nearly sticking heel and a flat-foot impact: the
    error falls with the tolerance (two decades of tolerance, more than one decade of error),
    the work grows, and the default meets the accuracy rule with fewer than half the
    evaluations of the fixed-step preset (RK4_LIMEX x 8 per 20 ms)."""
    ref, sw_ref = sliding_reference
    errs, evals = [], []
    for tol in (1e-4, 1e-6):
        got, sw = _sliding_heel_run(params, DEFAULT_OPTIONS.replace(step_tol=tol, strict=False))
        assert len(sw) == len(sw_ref) == 2
        errs.append(max(np.abs(got - ref).max(), np.abs(sw - sw_ref).max()))
        evals.append(_evaluations(params, DEFAULT_OPTIONS.replace(step_tol=tol)))
    assert errs[1] < 0.1 * errs[0] and evals[1] > evals[0]
    got, sw = _sliding_heel_run(params, DEFAULT_OPTIONS.replace(strict=False))
    assert np.abs(got - ref).max() <= 1e-3 and np.abs(sw - sw_ref).max() <= 1e-3
    assert _evaluations(params, DEFAULT_OPTIONS) < 0.5 * _evaluations(params, FIXED_STEP_OPTIONS)


def test_accurate_with_steps_beyond_the_explicit_stability_limit(params, sliding_reference):
    """Longest step 20 ms (one per period): fixed RK4 there is unstable in the joint damping
    (limit ~11 ms) and wrong on the sticking heel (test_simulator); the controller keeps the
    error-controlled method stable and within the accuracy rule."""
    ref, sw_ref = sliding_reference
    got, sw = _sliding_heel_run(params, DEFAULT_OPTIONS.replace(strict=False))
    assert len(sw) == len(sw_ref) == 2
    assert np.abs(got - ref).max() <= 1e-3 and np.abs(sw - sw_ref).max() <= 1e-3
    st = table2_periods(params, DEFAULT_OPTIONS)
    assert np.all(np.isfinite(st.qd)) and np.abs(st.qd).max() < 1e3


def _random_torque_run(params, options, seed, n=60, dt=0.005):
    """States (n, 12) and (mode, side) after each of n 5 ms periods of random torques
    (N(0, 10 N m), a new draw each period, as a controller changes them) from the sliding-heel
    scene's start."""
    from benchmarks.accuracy import scene_b_start

    rng = np.random.default_rng(seed)
    st = SimState(0.0, 2, 0, scene_b_start(params), np.zeros(6))
    out, modes = [], []
    for _ in range(n):
        st = step(params, st, np.tile(rng.normal(0.0, 10.0, 5), (4, 1)), dt, options).state
        out.append(np.r_[st.q, st.qd])
        modes.append((int(st.mode), st.stance_side))
    return np.array(out), modes


@pytest.mark.parametrize("seed", [0, 1])
def test_rates_are_accurate_at_5ms_control(params, seed):
    """At the walking task's 5 ms periods, with the torque changing every period, the default's
    joint rates stay within 1e-2 rad/s of a fine reference (RATE_ERROR_WEIGHT_S: a controller
    observes them), while one fixed 5 ms RK4_LIMEX step per period is off by ~5e-2 rad/s
    though its angles are within 1e-3 rad."""
    ref, modes_ref = _random_torque_run(params, REFERENCE.replace(strict=False), seed)
    fixed5 = SimOptions(integrator="rk4_limex", substeps=1, strict=False)
    rate_err = {}
    for name, opts in (("default", DEFAULT_OPTIONS.replace(strict=False)), ("fixed", fixed5)):
        got, modes = _random_torque_run(params, opts, seed)
        same = np.array([a == b for a, b in zip(modes, modes_ref, strict=True)])
        assert same.sum() >= len(same) - 1  # one period may end either side of a switch
        err = np.abs(got - ref)[same]
        assert err[:, :6].max() <= 1e-3
        rate_err[name] = err[:, 6:].max()
    assert rate_err["default"] <= 1e-2 < rate_err["fixed"]


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
        advance(params, arrays, tau, DT, DEFAULT_OPTIONS)
        st = step(params, st, tau[0], DT, DEFAULT_OPTIONS).state
        batched = arrays.get(0)
        np.testing.assert_array_equal(batched.q, st.q)
        np.testing.assert_array_equal(batched.qd, st.qd)
        assert batched.next_step_s == st.next_step_s == arrays.fst[0, FS_H]
        assert 0.0 < st.next_step_s <= DT / DEFAULT_OPTIONS.substeps
        if k == 3:
            mid = st  # just after the heel strike: the controller is taking short steps
    # forgetting the next step changes the steps taken (so it is really carried)
    assert mid.next_step_s < 0.5 * DT / DEFAULT_OPTIONS.substeps
    fresh = SimState(mid.t, mid.mode, mid.stance_side, mid.q, mid.qd, mid.root_y)
    a = step(params, mid, tau[0], DT, DEFAULT_OPTIONS).state
    b = step(params, fresh, tau[0], DT, DEFAULT_OPTIONS).state
    assert not np.array_equal(a.q, b.q)


@pytest.mark.parametrize("bad", [0.0, -1e-4, float("nan"), float("inf")])
def test_bad_tolerance_and_next_step_raise(bad):
    with pytest.raises(ValueError, match="step_tol"):
        SimOptions(step_tol=bad)
    if bad != 0.0:
        with pytest.raises(ValueError, match="next_step_s"):
            SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6), next_step_s=bad)
