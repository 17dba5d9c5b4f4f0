"""Newton-Euler dynamics against independent routes.

The independent route is a Lagrangian derivation in plain numpy: link COM positions and
absolute angles as functions of q, differentiated by the complex step (exact to round-off),
giving M = sum m Jv^T Jv + I Jw^T Jw, g = dV/dq and the Coriolis term Mdot qd - 1/2 d(qd^T M qd)/dq.
"""

import numpy as np
import pytest

from biped_constraint_env import dynamics as dyn
from biped_constraint_env.model import COL_ANGLE, COL_COM, COL_INERTIA, COL_MASS, COL_NEXT

RTOL_ROUTES = 1e-12  # RNEA columns vs CRBA: both exact, only round-off differs
RTOL_INDEPENDENT = 1e-9  # issue requirement for the Lagrangian route
CS = 1e-30  # complex-step size


def _coms(ch, q):
    """(6, 2) COM positions and (6,) absolute angles, complex-safe."""
    phi = np.cumsum(ch[:, COL_ANGLE] + q)
    o = np.zeros(2, dtype=q.dtype)
    coms = []
    for i in range(6):
        u = np.array([np.cos(phi[i]), np.sin(phi[i])])
        coms.append(o + ch[i, COL_COM] * u)
        o = o + ch[i, COL_NEXT] * u
    return np.array(coms), phi


def _jacobians(ch, q):
    jv = np.zeros((6, 2, 6))
    jw = np.zeros((6, 6))
    for j in range(6):
        qc = q.astype(complex)
        qc[j] += 1j * CS
        c, phi = _coms(ch, qc)
        jv[:, :, j] = c.imag / CS
        jw[:, j] = phi.imag / CS
    return jv, jw


def _mass_matrix_lagrange(ch, q):
    jv, jw = _jacobians(ch, q)
    M = np.zeros((6, 6))
    for i in range(6):
        M += ch[i, COL_MASS] * jv[i].T @ jv[i] + ch[i, COL_INERTIA] * np.outer(jw[i], jw[i])
    return M


def _mass_matrix_analytic_complex(ch, q):
    """M with analytic (z x r) Jacobians, complex-safe, for differentiating M itself."""
    c, phi = _coms(ch, q)
    o = np.zeros((6, 2), dtype=q.dtype)
    for i in range(1, 6):
        o[i] = o[i - 1] + ch[i - 1, COL_NEXT] * np.array([np.cos(phi[i - 1]), np.sin(phi[i - 1])])
    M = np.zeros((6, 6), dtype=q.dtype)
    for i in range(6):
        jv = np.zeros((2, 6), dtype=q.dtype)
        for j in range(i + 1):
            jv[0, j] = -(c[i, 1] - o[j, 1])
            jv[1, j] = c[i, 0] - o[j, 0]
        jw = np.zeros(6)
        jw[: i + 1] = 1.0
        M = M + ch[i, COL_MASS] * jv.T @ jv + ch[i, COL_INERTIA] * np.outer(jw, jw)
    return M


def _dM(ch, q):
    out = np.zeros((6, 6, 6))
    for k in range(6):
        qc = q.astype(complex)
        qc[k] += 1j * CS
        out[k] = _mass_matrix_analytic_complex(ch, qc).imag / CS
    return out


def _gravity_lagrange(ch, q, g):
    grad = np.zeros(6)
    for k in range(6):
        qc = q.astype(complex)
        qc[k] += 1j * CS
        c, _ = _coms(ch, qc)
        grad[k] = (g * ch[:, COL_MASS] * c[:, 1]).sum().imag / CS
    return grad


@pytest.fixture(params=range(5))
def state(request):
    r = np.random.default_rng(100 + request.param)
    return r.normal(size=6), 2 * r.normal(size=6), 50 * r.normal(size=6)


def test_mass_matrix_routes_agree(chain, state):
    q, _, _ = state
    m_rnea = dyn.mass_matrix_rnea(chain, q)
    m_crba = dyn.mass_matrix(chain, q)
    assert np.abs(m_rnea - m_crba).max() <= RTOL_ROUTES * np.abs(m_crba).max()


def test_mass_matrix_symmetric_positive_definite(chain, state):
    M = dyn.mass_matrix(chain, state[0])
    assert np.abs(M - M.T).max() == 0.0
    assert np.linalg.eigvalsh(M).min() > 0.0


def test_mass_matrix_matches_lagrangian_route(chain, state):
    q = state[0]
    ref = _mass_matrix_lagrange(chain.packed, q)
    assert np.abs(dyn.mass_matrix(chain, q) - ref).max() <= RTOL_INDEPENDENT * np.abs(ref).max()


def test_gravity_is_potential_gradient(chain, state):
    q = state[0]
    ref = _gravity_lagrange(chain.packed, q, chain.gravity_mps2)
    got = dyn.bias_forces(chain, q, np.zeros(6))
    assert np.abs(got - ref).max() <= RTOL_INDEPENDENT * np.abs(ref).max()


def test_coriolis_matches_lagrangian_route(chain, state):
    q, qd, _ = state
    dM = _dM(chain.packed, q)
    mdot = np.einsum("kij,k->ij", dM, qd)
    ref = mdot @ qd - 0.5 * np.einsum("i,kij,j->k", qd, dM, qd)
    got = dyn.bias_forces(chain, q, qd) - dyn.bias_forces(chain, q, np.zeros(6))
    assert np.abs(got - ref).max() <= RTOL_INDEPENDENT * np.abs(ref).max()


def test_rnea_equals_m_qdd_plus_bias(chain, state):
    q, qd, qdd = state
    lhs = dyn.rnea(chain, q, qd, qdd)
    rhs = dyn.mass_matrix(chain, q) @ qdd + dyn.bias_forces(chain, q, qd)
    assert np.abs(lhs - rhs).max() <= 1e-12 * np.abs(lhs).max()


def test_mirror_image_flips_every_torque(chain, state):
    """Reflect y -> -y: phi -> pi - phi, so q0 -> pi - q0, q_i -> -q_i - 2 offset_i."""
    q, qd, qdd = state
    off = chain.packed[:, COL_ANGLE]
    qm = -q - 2 * off
    qm[0] = np.pi - q[0]
    assert dyn.rnea(chain, qm, -qd, -qdd) == pytest.approx(-dyn.rnea(chain, q, qd, qdd), abs=1e-10)


def test_static_ankle_force_equals_weight_above(chain, params):
    q = np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])
    res = dyn.rnea_full(chain, q, np.zeros(6), np.zeros(6))
    g = params.gravity_mps2
    above = params.total_mass_kg - params.links[0].mass_kg
    assert res.joint_force[1] == pytest.approx([0.0, above * g], abs=1e-12)
    assert res.joint_force[0] == pytest.approx([0.0, params.total_mass_kg * g], abs=1e-12)


def test_external_force_enters_as_jacobian_transpose(chain, state):
    from biped_constraint_env.kinematics import point_jacobian

    q, qd, qdd = state
    f = np.array([3.0, -7.0])
    with_f = dyn.rnea_full(chain, q, qd, qdd, ext_link=5, ext_offset_m=0.25, ext_force_n=f).tau
    without = dyn.rnea(chain, q, qd, qdd)
    assert without - with_f == pytest.approx(point_jacobian(chain, q, 5, 0.25).T @ f, abs=1e-10)
