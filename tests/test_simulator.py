"""The hybrid simulator: energy, convergence, stability, drift, named events, bad input."""

import dataclasses

import numpy as np
import pytest
from conftest import STANCE_POSTURE, TABLE2_NM
from states import model3_state, model4_state

from biped_constraint_env import dynamics as dyn
from biped_constraint_env import kinematics as kin
from biped_constraint_env.model import PAPER_LINKS, paper_biped
from biped_constraint_env.modes import EventCode, Mode
from biped_constraint_env.simulator import (
    DEFAULT_OPTIONS,
    SimOptions,
    SimState,
    SimulationError,
    evaluate,
    integrate_mode,
    step,
)

RTOL_ENERGY = 1e-6  # issue requirement
DT = 0.02  # the paper's sampling time [s]


def _integrate(params, state, tau, h, n, options):
    for _ in range(n):
        state = integrate_mode(params, state, tau, h, options)
    return state


def _start(mode):
    q = STANCE_POSTURE.copy()
    qd = np.array([0.0, 0.5, -0.3, 0.8, -0.5, 0.2])
    if mode == 2:
        q[0], qd[0] = -0.05, -0.3
    return SimState(0.0, mode, 0, q, qd)


@pytest.mark.parametrize("integrator", ["rk4", "limex", "rk4_limex"])
@pytest.mark.parametrize("mode", [1, 2])
def test_energy_balance_with_damping(params, mode, integrator):
    """tau = 0: E(t) + dissipated work = E(0), work = int qd^T D qd dt (Simpson's rule).

    LIMEX is second order: its balance closes to its own truncation error (h = 0.2 ms)."""
    opts = SimOptions(integrator=integrator)
    ch = params.chain(0)
    D = dyn.damping_matrix(ch)
    h, n = 2e-4, 500
    st = _start(mode)
    e0 = sum(dyn.energy(ch, st.q, st.qd))
    powers = [st.qd @ D @ st.qd]
    for _ in range(n):
        st = integrate_mode(params, st, np.zeros(5), h, opts)
        powers.append(st.qd @ D @ st.qd)
    p = np.array(powers)
    work = h / 3 * (p[0] + p[-1] + 4 * p[1:-1:2].sum() + 2 * p[2:-1:2].sum())
    e1 = sum(dyn.energy(ch, st.q, st.qd))
    assert work > 0.1  # [J] the damping really dissipates something here
    rtol = 1e-4 if integrator == "limex" else RTOL_ENERGY
    assert abs(e1 + work - e0) <= rtol * abs(e0)


@pytest.mark.parametrize("mode", [1, 2])
def test_energy_conserved_without_damping(mode):
    links = tuple(dataclasses.replace(k, damping_nms_per_rad=0.0) for k in PAPER_LINKS)
    p = paper_biped(links=links)
    ch = p.chain(0)
    st = _start(mode)
    e0 = sum(dyn.energy(ch, st.q, st.qd))
    st = _integrate(p, st, np.zeros(5), 2e-4, 500, SimOptions(integrator="rk4"))
    assert abs(sum(dyn.energy(ch, st.q, st.qd)) - e0) <= RTOL_ENERGY * abs(e0)


@pytest.mark.parametrize(
    "integrator,ns,expected",
    [
        ("euler", (64, 128, 256), 2.0),
        ("semi_implicit", (64, 128, 256), 2.0),
        ("rk2", (32, 64, 128), 4.0),
        ("rk4", (16, 32, 64), 16.0),
        ("limex", (16, 32, 64), 4.0),
        ("rk4_limex", (16, 32, 64), 16.0),
    ],
)
def test_convergence_order(params, integrator, ns, expected):
    """Model 1, Table 2 torques, 40 ms: the error ratio under halving the step."""
    T = 0.04
    st = SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6))
    tau = TABLE2_NM[0]
    ref = _integrate(params, st, tau, T / 4096, 4096, SimOptions(integrator="rk4")).q
    opts = SimOptions(integrator=integrator)
    errs = [np.abs(_integrate(params, st, tau, T / n, n, opts).q - ref).max() for n in ns]
    ratios = [errs[0] / errs[1], errs[1] / errs[2]]
    assert ratios[-1] == pytest.approx(expected, rel=0.2), (errs, ratios)


def _diverges(params, integrator, h, t_end=1.0):
    st = SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6))
    opts = SimOptions(integrator=integrator, project_constraints=False)
    try:
        st = _integrate(params, st, TABLE2_NM[0], h, int(round(t_end / h)), opts)
    except SimulationError:
        return True
    return bool(np.abs(st.qd).max() > 1e6)


@pytest.mark.parametrize(
    "integrator,h,diverges",
    [
        ("euler", 0.020, True),
        ("euler", 0.010, True),
        ("euler", 0.005, False),
        ("rk4", 0.020, True),
        ("rk4", 0.012, True),
        ("rk4", 0.008, False),
        ("semi_implicit", 0.020, False),
        ("semi_implicit", 0.040, False),
        ("limex", 0.020, False),
        ("limex", 0.040, False),
        ("rk4_limex", 0.012, True),  # the switch is for the friction; damping is RK4's
        ("rk4_limex", 0.008, False),
    ],
)
def test_stability_region_model1_table2(params, integrator, h, diverges):
    """Stiff mode lambda ~ 257 1/s: Euler needs h < 7.8 ms, RK4 h < 10.8 ms; semi-implicit any."""
    assert _diverges(params, integrator, h) is diverges


def table2_periods(params, options, n=50):
    """Up to n 20 ms periods of Table 2's torques from the nominal posture (lenient checks);
    the last state."""
    st = SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6))
    for _ in range(n):
        res = step(params, st, TABLE2_NM, DT, options.replace(strict=False))
        st = res.state
        if res.terminated:
            break
    return st


def test_default_is_stable_at_20ms(params):
    st = table2_periods(params, DEFAULT_OPTIONS)
    assert np.all(np.isfinite(st.qd)) and np.abs(st.qd).max() < 1e3


@pytest.mark.parametrize("which", [3, 4])
def test_constraint_residual_over_a_phase(params, which):
    st = model3_state(params.chain(0)) if which == 3 else model4_state(params)
    opts = DEFAULT_OPTIONS.replace(strict=False)
    tau = np.zeros(5)
    worst, n = 0.0, 0
    for _ in range(10):
        res = step(params, st, tau, DT, opts)
        if res.state.mode != which or res.terminated:
            break
        st = res.state
        off = params.chain(st.stance_side).packed_scalars[4 if which == 3 else 5]
        z = kin.point_position(params.chain(st.stance_side), st.q, 5, off, st.root_y)[1]
        worst = max(worst, abs(z))
        n += 1
    assert n >= 3
    assert worst <= 1e-6


def _term(params, state, tau, options=DEFAULT_OPTIONS, dt=DT):
    return step(params, state, tau, dt, options)


def _find_tau(params, state, index, candidates):
    for tau in candidates:
        f = evaluate(params, state, tau)
        if index(f):
            return tau
    raise AssertionError("no candidate torque produced the condition")


AXES = [s * 150.0 * np.eye(5)[k] for k in range(5) for s in (1, -1)]


def test_event_stance_foot_tips_back(params):
    st = SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6))
    res = _term(params, st, np.array([-200.0, 0, 0, 0, 0]))
    assert res.terminated and res.termination == EventCode.STANCE_FOOT_TIPS_BACK


def test_event_stance_heel_down(params):
    q = STANCE_POSTURE.copy()
    q[0] = 0.01
    res = _term(params, SimState(0.0, 2, 0, q, np.zeros(6)), np.zeros(5))
    assert res.termination == EventCode.STANCE_HEEL_DOWN


def test_event_swing_toe_strike(params):
    st = model3_state(params.chain(0), phi5=-0.15, heel_z=0.05)  # toe 2.5 cm below, ankle above
    res = _term(params, dataclasses.replace(st, mode=Mode.TOE_PIVOT), np.zeros(5))
    assert res.termination == EventCode.SWING_TOE_STRIKE


def test_event_swing_foot_touchdown_in_model1(params):
    q = np.array([0.0, 0.0, 0.0, 0.0, 0.0, -0.3])  # legs together, swing toe 7 cm into the floor
    res = _term(params, SimState(0.0, 1, 0, q, np.zeros(6)), np.zeros(5))
    assert res.termination == EventCode.SWING_FOOT_TOUCHDOWN


def test_event_body_below_ground(params):
    q = np.array([0.0, -1.7, 1.7, 0.0, 0.0, 0.0])  # stance shank past horizontal: knees below
    res = _term(params, SimState(0.0, 1, 0, q, np.zeros(6)), np.zeros(5))
    assert res.termination == EventCode.BODY_BELOW_GROUND


def test_event_swing_heel_pulls(params):
    st = model3_state(params.chain(0))
    others = [k for k in range(1, 9) if k != EventCode.SWING_HEEL_PULLS]
    tau = _find_tau(params, st, lambda f: f[1][2] < 0 and np.all(f[2][others] > 0), AXES)
    assert _term(params, st, tau).termination == EventCode.SWING_HEEL_PULLS


def test_event_stance_toe_pulls(params):
    st = dataclasses.replace(model3_state(params.chain(0), swing_thigh=0.3), mode=Mode.TOE_PIVOT)
    st = dataclasses.replace(st, q=st.q + np.array([0, 0, 0, 0.3, 0, 0]))  # heel up off the floor
    tau = _find_tau(params, st, lambda f: f[1][0] < 0 and np.all(f[2][1:7] > 0), AXES)
    assert _term(params, st, tau).termination == EventCode.STANCE_TOE_PULLS


def test_event_stance_foot_pulls(params):
    st = model4_state(params)
    tau = _find_tau(params, st, lambda f: f[2][0] > 0 and min(f[1][:2]) < 0, AXES)
    assert _term(params, st, tau).termination == EventCode.STANCE_FOOT_PULLS


def test_event_step_behind_stance_toe(params):
    st = model3_state(params.chain(0), swing_thigh=-0.3, theta0=-0.05)
    res = _term(params, dataclasses.replace(st, mode=Mode.TOE_PIVOT), np.zeros(5))
    assert res.termination == EventCode.STEP_BEHIND_STANCE_TOE


def test_event_zeno(params):
    st = dataclasses.replace(model3_state(params.chain(0), phi5=0.0), mode=Mode.TOE_PIVOT)
    res = _term(params, st, np.zeros(5), DEFAULT_OPTIONS.replace(max_switches=1))
    assert res.termination == EventCode.ZENO
    assert [e.code for e in res.events[:2]] == [EventCode.MODE_SWITCH] * 2


def test_lenient_records_force_violation_and_goes_on(params):
    st = SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6))
    res = _term(params, st, np.array([-200.0, 0, 0, 0, 0]), DEFAULT_OPTIONS.replace(strict=False))
    tips = [e for e in res.events if e.code == EventCode.STANCE_FOOT_TIPS_BACK]
    assert len(tips) == 1 and not tips[0].terminal


def test_non_finite_raises_with_last_finite_state():
    links = tuple(dataclasses.replace(k, damping_nms_per_rad=1e300) for k in PAPER_LINKS)
    p = paper_biped(links=links)
    st = SimState(0.0, 1, 0, STANCE_POSTURE, np.full(6, 1.0) * [0, 1, 1, 1, 1, 1])
    opts = SimOptions(integrator="euler", substeps=4, strict=False)
    with pytest.raises(SimulationError) as info:
        step(p, st, np.zeros(5), DT, opts)
    assert np.all(np.isfinite(info.value.state.q))


def test_located_switch_time_is_precise(params):
    """2 -> 3: stepping to just before / after the located time brackets the switch."""
    st = model3_state(params.chain(0), phi5=0.1, heel_z=0.002)
    st = dataclasses.replace(st, mode=Mode.TOE_PIVOT)
    opts = DEFAULT_OPTIONS.replace(strict=False)
    for _ in range(20):
        res = step(params, st, np.zeros(5), DT, opts)
        sw = [e for e in res.events if e.code == EventCode.MODE_SWITCH and e.mode_from == 2]
        if sw:
            break
        st = res.state
    assert sw and st.t < sw[0].t < st.t + DT
    lag = sw[0].t - st.t
    # same substep length for the part before the event: one substep of exactly `lag` +- 2 us
    fine = opts.replace(substeps=1)
    before = step(params, st, np.zeros(5), lag - 2e-6, fine)
    after = step(params, st, np.zeros(5), lag + 2e-6, fine)
    assert before.state.mode == Mode.TOE_PIVOT
    assert after.state.mode == Mode.TOE_HEEL


@pytest.mark.parametrize(
    "bad", [np.full(5, np.nan), np.zeros(4), np.full(5, np.inf), np.zeros((3, 5))]
)
def test_bad_torque_raises(params, bad):
    with pytest.raises(ValueError, match="tau"):
        step(params, SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6)), bad, DT)


def test_bad_state_and_options_raise(params):
    with pytest.raises(ValueError, match="q"):
        SimState(0.0, 1, 0, np.zeros(5), np.zeros(6))
    with pytest.raises(ValueError, match="qd"):
        SimState(0.0, 1, 0, np.zeros(6), np.full(6, np.nan))
    with pytest.raises(ValueError):
        SimState(0.0, 5, 0, np.zeros(6), np.zeros(6))
    with pytest.raises(ValueError, match="integrator"):
        SimOptions(integrator="leapfrog")
    with pytest.raises(ValueError, match="substeps"):
        SimOptions(substeps=0)
    with pytest.raises(ValueError, match="dt"):
        step(params, SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6)), np.zeros(5), -1.0)


def test_switches_follow_the_mode_table(params):
    """Every model switch goes to the table's successor; legs swap exactly at 3 -> 4."""
    st = model3_state(params.chain(0), phi5=0.05)
    opts = DEFAULT_OPTIONS.replace(strict=False)
    seen = []
    for _ in range(40):
        res = step(params, st, np.zeros(5), DT, opts)
        seen += [(e.mode_from, e.mode_to) for e in res.events if e.code == EventCode.MODE_SWITCH]
        if res.state.stance_side != st.stance_side:
            assert (3, 4) in seen
        st = res.state
        if res.terminated:
            break
    assert (3, 4) in seen
    for a, b in seen:
        assert b == a % 4 + 1


def test_table2_run_with_located_events_follows_mode_order(params):
    """Table 2 (paper signs), nominal posture, located events, lenient: the switches it makes
    follow 1 -> 2 -> 3 -> 4 -> 1. (No reading found so far completes a cycle: README.)"""
    st = SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6))
    opts = DEFAULT_OPTIONS.replace(strict=False)
    switches = []
    for _ in range(100):
        res = step(params, st, TABLE2_NM, DT, opts)
        switches += [e for e in res.events if e.code == EventCode.MODE_SWITCH]
        st = res.state
        if res.terminated:
            break
    assert switches and switches[0].mode_from == 1 and switches[0].mode_to == 2
    for e in switches:
        assert e.mode_to == e.mode_from % 4 + 1
    assert all(b.t >= a.t for a, b in zip(switches, switches[1:], strict=False))


def test_flat_landing_is_a_switch_not_an_ankle_below_ground(params):
    """At 3 -> 4 the swing ankle reaches z = 0 with the flat foot; that must not end the run."""
    st = model3_state(params.chain(0), phi5=0.02)
    seen = []
    for _ in range(30):
        res = step(params, st, np.zeros(5), DT, DEFAULT_OPTIONS.replace(strict=False))
        seen += [e.code for e in res.events]
        st = res.state
        if (3, 4) in [(e.mode_from, e.mode_to) for e in res.events] or res.terminated:
            break
    assert EventCode.MODE_SWITCH in seen and EventCode.BODY_BELOW_GROUND not in seen[:1]


def test_stop_at_switch_hands_control_back_at_the_switch():
    """stop_at_switch ends the period at the first switch (impact and renumbering applied);
    finishing the period from there with the same torques lands where the full period does."""
    params = paper_biped()
    s = model3_state(params.chain(0), phi5=0.05)
    tau = np.zeros(5)
    for _ in range(50):
        full = step(params, s, tau, 0.02, DEFAULT_OPTIONS)
        if full.events:
            break
        s = full.state
    switch = full.events[0]
    assert switch.code == EventCode.MODE_SWITCH and (switch.mode_from, switch.mode_to) == (3, 4)
    part = step(params, s, tau, 0.02, DEFAULT_OPTIONS.replace(stop_at_switch=True))
    assert not part.terminated and len(part.events) == 1
    assert part.state.t == pytest.approx(switch.t, abs=1e-12) and part.state.t < s.t + 0.02
    assert int(part.state.mode) == 4 and part.state.stance_side == 1  # renumbered
    rest = step(params, part.state, tau, s.t + 0.02 - part.state.t, DEFAULT_OPTIONS)
    assert rest.state.t == pytest.approx(full.state.t, abs=1e-12)
    np.testing.assert_allclose(rest.state.q, full.state.q, atol=1e-5)
    np.testing.assert_allclose(rest.state.qd, full.state.qd, atol=1e-3)
    # without a switch in the period, the option changes nothing
    quiet = step(params, full.state, tau, 0.001, DEFAULT_OPTIONS.replace(stop_at_switch=True))
    same = step(params, full.state, tau, 0.001, DEFAULT_OPTIONS)
    np.testing.assert_array_equal(quiet.state.q, same.state.q)


def _sliding_heel_run(params, options, T=0.3):
    """The accuracy study's scene (b): model 2 -> 3 (heel strike, the heel then slides and
    nearly sticks: friction slope K f_n / eps ~ 1e4 N s/m) -> 4, zero torque, 20 ms periods."""
    from benchmarks.accuracy import scene_b_start

    st = SimState(0.0, 2, 0, scene_b_start(params), np.zeros(6))
    angles, switches = [], []
    for _ in range(int(round(T / DT))):
        res = step(params, st, np.zeros((4, 5)), DT, options)
        st = res.state
        switches += [e.t for e in res.events if e.code == EventCode.MODE_SWITCH]
        angles.append(np.cumsum(params.chain(st.stance_side).packed[:, 4] + st.q))
    return np.array(angles), np.array(switches)


def test_limex_accurate_through_a_stiff_contact_at_20ms(params):
    """At the paper's 20 ms, beyond every explicit method's stability limit (RK4's is ~0.2 ms
    on the sticking heel; the saturating friction keeps it bounded but wrong: 0.013 rad, the
    heel strike 10 ms early), LIMEX with one step per period meets the accuracy rule."""
    ref, sw_ref = _sliding_heel_run(params, SimOptions(integrator="rk4", substeps=400))
    got, sw = _sliding_heel_run(params, SimOptions(integrator="limex", substeps=1))
    assert len(sw) == len(sw_ref) == 2
    assert np.abs(got - ref).max() <= 1e-3 and np.abs(sw - sw_ref).max() <= 1e-3
    got, sw = _sliding_heel_run(params, SimOptions(integrator="rk4", substeps=1))
    assert np.abs(got - ref).max() > 1e-3 and np.abs(sw - sw_ref).max() > 1e-3


def test_rk4_limex_switches_to_limex_only_where_the_friction_is_stiff(params):
    """On the sticking heel at 5 ms, RK4 is bounded but wrong and LIMEX right; the switching
    method takes the stiff steps by LIMEX (its result then differs from RK4's) and meets the
    accuracy rule; in model 1 (no point contact) it is RK4, bit for bit."""
    from biped_constraint_env.integrators import friction_is_stiff

    assert friction_is_stiff(0.0, 0.005) and not friction_is_stiff(0.0, 1e-6)
    assert not friction_is_stiff(0.99999, 0.005)  # sliding at ~220 eps
    ref, sw_ref = _sliding_heel_run(params, SimOptions(integrator="rk4", substeps=400))
    got, sw = _sliding_heel_run(params, SimOptions(integrator="rk4_limex", substeps=4))
    rk4, sw4 = _sliding_heel_run(params, SimOptions(integrator="rk4", substeps=4))
    assert len(sw) == len(sw_ref) == 2
    assert np.abs(got - ref).max() <= 1e-3 and np.abs(sw - sw_ref).max() <= 1e-3
    assert np.abs(got - ref).max() < 0.5 * np.abs(rk4 - ref).max()
    st = SimState(0.0, 1, 0, STANCE_POSTURE, np.zeros(6))
    a = _integrate(params, st, TABLE2_NM[0], 0.005, 20, SimOptions(integrator="rk4"))
    b = _integrate(params, st, TABLE2_NM[0], 0.005, 20, SimOptions(integrator="rk4_limex"))
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.qd, b.qd)
