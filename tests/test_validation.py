"""Independent engines (optional dependencies; skipped when absent) and study pieces."""

import numpy as np
import pytest

from biped_constraint_env import dynamics as dyn
from biped_constraint_env.hybrid import nb_make_work, nb_solve_mode_w
from biped_constraint_env.simulator import SimOptions, SimState, integrate_mode

RTOL_ENGINE = 1e-12  # issue requirement for Pinocchio; MuJoCo's M is exact to round-off too
POSTURES = [np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7]), np.array([0.0, 0.3, -0.6, 0.9, -1.2, 0.4])]


@pytest.mark.parametrize("q", POSTURES)
def test_mujoco_mjcf_mass_matrix_matches(chain, q):
    pytest.importorskip("mujoco")
    from benchmarks.mujoco_model import build, mass_matrix

    model, data = build(chain)
    ours = dyn.mass_matrix(chain, q)[1:, 1:]
    assert np.abs(mass_matrix(model, data, q[1:]) - ours).max() <= RTOL_ENGINE * np.abs(ours).max()


@pytest.mark.parametrize("q", POSTURES)
def test_pinocchio_mass_matrix_and_bias_match(chain, rng, q):
    pin = pytest.importorskip("pinocchio")
    from benchmarks.pin_model import build

    model, data = build(chain)
    qq = q.copy()
    qq[0] = -0.2
    qd = rng.normal(size=6)
    M = pin.crba(model, data, qq)
    M = np.triu(M) + np.triu(M, 1).T
    ours = dyn.mass_matrix(chain, qq)
    assert np.abs(M - ours).max() <= RTOL_ENGINE * np.abs(ours).max()
    b = pin.rnea(model, data, qq, qd, np.zeros(6))
    assert np.abs(b - dyn.bias_forces(chain, qq, qd)).max() <= RTOL_ENGINE * np.abs(b).max()


def test_solver_mass_matrix_routes_agree(params, rng):
    ch = params.chain(0)
    q = POSTURES[0].copy()
    q[0] = -0.1
    qd = rng.normal(size=6)
    tau = np.concatenate([[0.0], rng.normal(scale=20, size=5)])
    out = []
    for columns in (False, True):
        W = nb_make_work()
        args = (ch.packed, ch.packed_scalars, 3, q, qd, tau, 0.0, 0.0, 1e-3, W, columns)
        fn = nb_solve_mode_w(*args)[0]
        out.append((W[10].copy(), fn))
    assert np.abs(out[0][0] - out[1][0]).max() < 1e-10 and out[0][1] == pytest.approx(out[1][1])


def test_mujoco_trajectory_agrees(params):
    pytest.importorskip("mujoco")
    from benchmarks.mujoco_model import build, simulate

    ch = params.chain(0)
    q0 = POSTURES[0]
    tau = np.array([10.0, 120.0, 35.0, 80.0, 0.0])
    model, data = build(ch, 1e-4)
    _, q_mj = simulate(model, data, q0[1:], tau, 0.05, 100)
    st = SimState(0.0, 1, 0, q0, np.zeros(6))
    opts = SimOptions(integrator="rk4")
    ours = [q0[1:]]
    for k in range(500):
        st = integrate_mode(params, st, tau, 1e-4, opts)
        if (k + 1) % 100 == 0:
            ours.append(st.q[1:])
    assert np.abs(np.array(ours) - q_mj).max() < 1e-9
