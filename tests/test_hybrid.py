"""Constrained solve, guards, reset maps (impacts, renumbering), projection."""

import numpy as np
import pytest
from states import model3_state, model4_state

from biped_constraint_env import dynamics as dyn
from biped_constraint_env import kinematics as kin
from biped_constraint_env.hybrid import nb_impact, nb_project, nb_renumber, nb_solve_mode
from biped_constraint_env.modes import MODE_TABLE, Mode
from biped_constraint_env.simulator import evaluate

ATOL_RESIDUAL = 1e-9  # [m/s^2] round-off of a 7x7 solve with entries up to ~1e2


def _tau6(tau5):
    return np.concatenate([[0.0], tau5])


@pytest.mark.parametrize("mode", [1, 2, 3, 4])
def test_mode_table_unknowns_match_paper(mode):
    assert MODE_TABLE[Mode(mode)].n_unknowns == {1: 5, 2: 6, 3: 7, 4: 6}[mode]


@pytest.mark.parametrize("which", [3, 4])
def test_constrained_solve_satisfies_constraint_and_motion(params, rng, which):
    state = model3_state(params.chain(0)) if which == 3 else model4_state(params)
    ch = params.chain(state.stance_side)
    qd = rng.normal(size=6)
    if which == 4:
        qd[0] = 0.0
    tau = _tau6(rng.normal(scale=30, size=5))
    s = MODE_TABLE[Mode(which)].contact.end
    off = ch.packed_scalars[int(s)]
    qdd, fn, sg, _ = nb_solve_mode(
        ch.packed, ch.packed_scalars, which, state.q, qd, tau, 0.0, 0.0, 1e-3
    )
    J = kin.point_jacobian(ch, state.q, 5, off)
    jdot = kin.point_bias_acceleration(ch, state.q, qd, 5, off)
    # constraint at acceleration level (paper eq. 5): J_z qdd + Jdot_z qd = 0
    assert J[1] @ qdd + jdot[1] == pytest.approx(0.0, abs=ATOL_RESIDUAL)
    # equation of motion (paper eq. 4) on the model's unknowns
    s0 = 0 if which == 3 else 1
    M = dyn.mass_matrix(ch, state.q)
    b = dyn.bias_forces(ch, state.q, qd)
    D = dyn.damping_matrix(ch)
    gen = (J[1] - params.friction_ratio * sg * J[0]) * fn
    resid = M @ qdd + b + D @ qd - tau - gen
    assert np.abs(resid[s0:]).max() < 1e-9
    # friction opposes sliding
    v_slip = J[0] @ qd
    assert np.sign(sg) == np.sign(v_slip)


def test_model1_heel_toe_split_matches_root_wrench(params):
    """Paper eq. 18-19 from the ankle wrench (+ foot weight) equals the exact split at the toe."""
    from biped_constraint_env.simulator import DEFAULT_OPTIONS, SimState

    q = np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])
    st = SimState(0.0, 1, 0, q, np.zeros(6))
    tau = np.array([10.0, 20.0, -5.0, 3.0, 1.0])
    opts = DEFAULT_OPTIONS.replace(heel_force_includes_foot_weight=True)
    qdd, forces, _ = evaluate(params, st, tau, opts)
    res = dyn.rnea_full(params.chain(0), q, np.zeros(6), qdd)
    f_heel = -res.joint_moment[0] / params.links[0].length_m  # moment about the toe
    assert forces[1] == pytest.approx(f_heel, abs=1e-9)
    assert forces[0] + forces[1] == pytest.approx(res.joint_force[0, 1], abs=1e-9)
    # the paper's reading leaves the foot's weight out: each end carries m0 g / 2 less
    paper = evaluate(params, st, tau, opts.replace(heel_force_includes_foot_weight=False))[1]
    w = params.links[0].mass_kg * params.gravity_mps2
    assert paper[:2] == pytest.approx(forces[:2] - w / 2, abs=1e-9)


def test_renumbering_keeps_world_pose_and_angular_velocity(params, rng):
    s3 = model3_state(params.chain(0), phi5=0.0)
    ch0, ch1 = params.chain(0), params.chain(1)
    qd = rng.normal(size=6)
    qn, qdn, root = nb_renumber(ch0.packed, ch1.packed, ch0.packed_scalars, s3.q, qd, 0.0)
    before = kin.keypoints(ch0, s3.q, 0.0)
    after = kin.keypoints(ch1, qn, root)
    names = list(kin.KEYPOINT_NAMES)
    swap = {
        n: n.replace("stance", "X").replace("swing", "stance").replace("X", "swing") for n in names
    }
    for i, n in enumerate(names):
        assert after[names.index(swap[n])] == pytest.approx(before[i], abs=1e-12), n
    w_before = np.cumsum(qd)
    w_after = np.cumsum(qdn)
    assert w_after == pytest.approx(w_before[::-1], abs=1e-12)


def test_plastic_heel_strike(params, rng):
    s3 = model3_state(params.chain(0))
    ch = params.chain(0)
    qd = rng.normal(size=6)
    qd_plus = nb_impact(ch.packed, ch.packed_scalars, 1, s3.q, qd, 1)
    heel = ch.packed_scalars[4]
    assert kin.point_velocity(ch, s3.q, qd_plus, 5, heel)[1] == pytest.approx(0.0, abs=1e-12)
    e_minus = dyn.energy(ch, s3.q, qd)[0]
    e_plus = dyn.energy(ch, s3.q, qd_plus)[0]
    assert e_plus <= e_minus
    assert e_plus < e_minus - 1e-6  # a generic strike does dissipate


def test_plastic_foot_flat_impact_brings_foot_to_rest(params, rng):
    s3 = model3_state(params.chain(0), phi5=0.0)
    ch = params.chain(0)
    qd = rng.normal(size=6)
    qd_plus = nb_impact(ch.packed, ch.packed_scalars, 2, s3.q, qd, 1)
    assert kin.point_velocity(ch, s3.q, qd_plus, 5, 0.0) == pytest.approx([0, 0], abs=1e-12)
    assert qd_plus.sum() == pytest.approx(0.0, abs=1e-12)  # foot angular velocity
    assert dyn.energy(ch, s3.q, qd_plus)[0] <= dyn.energy(ch, s3.q, qd)[0]


@pytest.mark.parametrize("reset", [1, 2])
def test_paper_impact_zeroes_all_velocities(params, rng, reset):
    ch = params.chain(0)
    s3 = model3_state(ch)
    out = nb_impact(ch.packed, ch.packed_scalars, reset, s3.q, rng.normal(size=6), 0)
    assert np.all(out == 0.0)


def test_projection_restores_contact(params, rng):
    s3 = model3_state(params.chain(0))
    ch = params.chain(0)
    q = s3.q + 1e-4 * rng.normal(size=6)
    qd = rng.normal(size=6)
    nb_project(ch.packed, ch.packed_scalars, 3, q, qd)
    heel = ch.packed_scalars[4]
    assert abs(kin.point_position(ch, q, 5, heel)[1]) < 1e-12
    assert abs(kin.point_velocity(ch, q, qd, 5, heel)[1]) < 1e-12


def test_guards_positive_inside_each_hand_built_state(params):
    s3 = model3_state(params.chain(0))
    _, _, g = evaluate(params, s3, np.zeros(5))
    assert np.all(g > 0)
    s4 = model4_state(params)
    _, _, g = evaluate(params, s4, np.zeros(5))
    assert np.all(g > 0)
