"""Recursive Newton-Euler inverse dynamics and the mass matrix (paper eq. 10-14).

The joint damping ``D qd`` is kept as a separate, explicit term (paper eq. 1), so
``rnea(q, qd, qdd) = M(q) qdd + h(q, qd) + g(q)`` and ``bias_forces(q, qd) = rnea(q, qd, 0)``.

Two routes to M:
- :func:`mass_matrix_rnea`: the paper's route, column i = INV(q, 0, e_i, 0) (eq. 14);
- :func:`mass_matrix` (CRBA): composite bodies, M[i, j] = Io_j + m_j^c (o_j - o_i).(c_j^c - o_j)
  for i <= j, where body j^c is links j..5 and Io_j its inertia about joint j.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .jit import njit_noalloc
from .kinematics import (
    K_AL,
    K_AY,
    K_AZ,
    K_COS,
    K_OY,
    K_OZ,
    K_SIN,
    K_W,
    NK,
    _vec6,
    nb_fk,
    nb_forward_pass,
)
from .model import (
    COL_COM,
    COL_INERTIA,
    COL_MASS,
    COL_NEXT,
    N_LINKS,
    SC_GRAVITY,
    SC_GRAVITY_T,
    ChainModel,
)


@njit_noalloc
def nb_rnea_backward(ch, K, g, gt, ext_link, ext_s, ext_fy, ext_fz, f, n):
    """Backward Newton-Euler pass over the kinematic table K of :func:`nb_fk`.

    Gravity enters as a base acceleration opposite to it, which shifts every joint-origin
    acceleration by (gt, g) (g normal to the ground, gt along it: (0, g) on flat ground), so
    one forward pass at g = 0 serves kinematics and dynamics.
    An external force (ext_fy, ext_fz) [N] acts at offset ext_s [m] on link ext_link (< 0:
    none). Fills f (6, 2) (force on link i from link i-1 at joint i [N]; row 0: from the
    ground) and n (6,) (moment about joint i [N m] = the joint torque, damping excluded).
    """
    fny = 0.0
    fnz = 0.0
    nn = 0.0
    for i in range(N_LINKS - 1, -1, -1):
        c = K[i, K_COS]
        s = K[i, K_SIN]
        w = K[i, K_W]
        al = K[i, K_AL]
        rcy = ch[i, COL_COM] * c
        rcz = ch[i, COL_COM] * s
        m = ch[i, COL_MASS]
        acy = K[i, K_AY] + gt - al * rcz - w * w * rcy
        acz = K[i, K_AZ] + g + al * rcy - w * w * rcz
        fy = m * acy + fny
        fz = m * acz + fnz
        mom = ch[i, COL_INERTIA] * al + rcy * m * acz - rcz * m * acy + nn
        if i < N_LINKS - 1:
            mom += ch[i, COL_NEXT] * (c * fnz - s * fny)
        if i == ext_link:
            fy -= ext_fy
            fz -= ext_fz
            mom -= ext_s * (c * ext_fz - s * ext_fy)
        f[i, 0] = fy
        f[i, 1] = fz
        n[i] = mom
        fny = fy
        fnz = fz
        nn = mom


@njit(cache=True)
def nb_rnea_full(ch, q, qd, qdd, g, gt, ext_link, ext_s, ext_f):
    """Inverse dynamics with the joint wrenches (paper eq. 11, damping excluded).

    Args:
        ch: (6, 6) packed chain. q, qd, qdd: (6,) [rad, rad/s, rad/s^2].
        g, gt: gravity normal to and along the ground [m/s^2] (0 to leave it out).
        ext_link, ext_s, ext_f: an external force ext_f (2,) [N] applied at offset ext_s [m] on
            link ext_link (ext_link < 0: none), e.g. a ground contact.

    Returns:
        tau (6,): joint torques [N m] that produce qdd;
        f (6, 2): force on link i from link i-1 at joint i (i = 0: from the ground) [N];
        n (6,): moment on link i from link i-1 about joint i [N m] (n = tau).
    """
    K = np.empty((N_LINKS, NK))
    nb_fk(ch, q, qd, qdd, 0.0, K)
    f = np.empty((N_LINKS, 2))
    n = np.empty(N_LINKS)
    nb_rnea_backward(ch, K, g, gt, ext_link, ext_s, ext_f[0], ext_f[1], f, n)
    return n.copy(), f, n


@njit(cache=True)
def nb_rnea(ch, q, qd, qdd, g, gt):
    """Joint torques [N m] (6,) = M qdd + h + g(q) (no damping, no external force)."""
    return nb_rnea_full(ch, q, qd, qdd, g, gt, -1, 0.0, np.zeros(2))[0]


@njit(cache=True)
def nb_mass_matrix_rnea(ch, q):
    """(6, 6) mass matrix, column i = INV(q, 0, e_i, 0) (paper eq. 14)."""
    z = np.zeros(N_LINKS)
    M = np.empty((N_LINKS, N_LINKS))
    for i in range(N_LINKS):
        e = np.zeros(N_LINKS)
        e[i] = 1.0
        M[:, i] = nb_rnea(ch, q, z, e, 0.0, 0.0)
    return M


@njit_noalloc
def nb_crba(ch, K, M, tmp):
    """Fill M (6, 6) by the composite-rigid-body algorithm from the table K.

    Body j^c = links j..5; M[i, j] = Io_j + m_j^c (o_j - o_i).(c_j^c - o_j) for i <= j, with Io_j
    its inertia about joint j. ``tmp`` is a (4, 6) scratch array.
    """
    cm = 0.0
    sy = 0.0
    sz = 0.0
    ic = 0.0  # sum of I_k + m_k |c_k|^2 about the world origin
    for j in range(N_LINKS - 1, -1, -1):
        m = ch[j, COL_MASS]
        oy = K[j, K_OY]
        oz = K[j, K_OZ]
        cy = oy + ch[j, COL_COM] * K[j, K_COS]
        cz = oz + ch[j, COL_COM] * K[j, K_SIN]
        cm += m
        sy += m * cy
        sz += m * cz
        ic += ch[j, COL_INERTIA] + m * (cy * cy + cz * cz)
        tmp[0, j] = cm
        tmp[1, j] = sy / cm - oy
        tmp[2, j] = sz / cm - oz
        # parallel-axis shift from the world origin to o_j
        tmp[3, j] = ic - 2.0 * (oy * sy + oz * sz) + cm * (oy * oy + oz * oz)
    for j in range(N_LINKS):
        for i in range(j + 1):
            v = tmp[3, j] + tmp[0, j] * (
                (K[j, K_OY] - K[i, K_OY]) * tmp[1, j] + (K[j, K_OZ] - K[i, K_OZ]) * tmp[2, j]
            )
            M[i, j] = v
            M[j, i] = v


@njit(cache=True)
def nb_mass_matrix(ch, q):
    """(6, 6) mass matrix by the composite-rigid-body algorithm (O(n^2), one pass)."""
    z = np.zeros(N_LINKS)
    K = np.empty((N_LINKS, NK))
    nb_fk(ch, q, z, z, 0.0, K)
    M = np.empty((N_LINKS, N_LINKS))
    nb_crba(ch, K, M, np.empty((4, N_LINKS)))
    return M


class RneaResult(NamedTuple):
    """Intermediates of one Newton-Euler pass (see :func:`rnea_full`)."""

    tau: np.ndarray
    """(6,) joint torques [N m] (damping excluded)."""
    joint_force: np.ndarray
    """(6, 2) force on link i from link i-1 at joint i [N] (row 0: from the ground)."""
    joint_moment: np.ndarray
    """(6,) moment on link i from link i-1 about joint i [N m]."""


def rnea_full(
    chain: ChainModel,
    q,
    qd,
    qdd,
    *,
    gravity: bool = True,
    ext_link: int = -1,
    ext_offset_m: float = 0.0,
    ext_force_n=(0.0, 0.0),
) -> RneaResult:
    """Newton-Euler inverse dynamics with joint wrenches (paper eq. 11-12).

    Args:
        chain: the chain in the current numbering.
        q, qd, qdd: (6,) joint angles [rad], rates [rad/s], accelerations [rad/s^2].
        gravity: include gravity (the ``g`` argument of the paper's INV).
        ext_link: link carrying an external force (-1: none).
        ext_offset_m: offset of its point of application along the link [m].
        ext_force_n: (2,) external force (y, z) [N].
    """
    g = chain.packed_scalars[SC_GRAVITY] if gravity else 0.0
    gt = chain.packed_scalars[SC_GRAVITY_T] if gravity else 0.0
    ext = np.asarray(ext_force_n, dtype=np.float64)
    tau, f, n = nb_rnea_full(
        chain.packed,
        _vec6("q", q),
        _vec6("qd", qd),
        _vec6("qdd", qdd),
        g,
        gt,
        int(ext_link),
        float(ext_offset_m),
        ext,
    )
    return RneaResult(tau, f, n)


def rnea(chain: ChainModel, q, qd, qdd, *, gravity: bool = True) -> np.ndarray:
    """(6,) joint torques [N m] = M(q) qdd + h(q, qd) + g(q) (damping excluded)."""
    return rnea_full(chain, q, qd, qdd, gravity=gravity).tau


def bias_forces(chain: ChainModel, q, qd) -> np.ndarray:
    """(6,) bias b = INV(q, qd, 0, g) = h(q, qd) + g(q) [N m] (paper eq. 13, damping excluded)."""
    return rnea(chain, q, qd, np.zeros(N_LINKS))


def mass_matrix_rnea(chain: ChainModel, q) -> np.ndarray:
    """(6, 6) M(q) [kg m^2], column by column with unit accelerations (paper eq. 14)."""
    return nb_mass_matrix_rnea(chain.packed, _vec6("q", q))


def mass_matrix(chain: ChainModel, q) -> np.ndarray:
    """(6, 6) M(q) [kg m^2] by the composite-rigid-body algorithm (the fast route)."""
    return nb_mass_matrix(chain.packed, _vec6("q", q))


@njit(cache=True)
def nb_energy(ch, q, qd, g, gt):
    """(kinetic, potential) energy [J] of the chain with its root at the origin.

    ``g``, ``gt``: gravity normal to and along the ground [m/s^2] (the potential of a point
    at (y, z) of the ground's frame is m (g z + gt y)).
    """
    phi, w, al, o, vo, ao = nb_forward_pass(ch, q, qd, np.zeros(N_LINKS), 0.0, 0.0)
    kinetic = 0.0
    potential = 0.0
    for i in range(N_LINKS):
        c = np.cos(phi[i])
        s = np.sin(phi[i])
        m = ch[i, COL_MASS]
        vy = vo[i, 0] - w[i] * ch[i, COL_COM] * s
        vz = vo[i, 1] + w[i] * ch[i, COL_COM] * c
        kinetic += 0.5 * (m * (vy * vy + vz * vz) + ch[i, COL_INERTIA] * w[i] * w[i])
        potential += m * (g * (o[i, 1] + ch[i, COL_COM] * s) + gt * (o[i, 0] + ch[i, COL_COM] * c))
    return kinetic, potential


def energy(chain: ChainModel, q, qd, root_y: float = 0.0) -> tuple[float, float]:
    """(kinetic, potential) energy [J]; potential measured from the ground's origin.

    On a slope the potential also depends on the root's place ``root_y`` [m] along the
    ground (flat ground: it does not).
    """
    sc = chain.packed_scalars
    kinetic, potential = nb_energy(
        chain.packed, _vec6("q", q), _vec6("qd", qd), sc[SC_GRAVITY], sc[SC_GRAVITY_T]
    )
    mass = sum(link.mass_kg for link in chain.links)
    return kinetic, potential + mass * sc[SC_GRAVITY_T] * float(root_y)


def damping_matrix(chain: ChainModel) -> np.ndarray:
    """(6, 6) diagonal joint damping D [N m s/rad] (joint 0 = toe pivot)."""
    return np.diag(np.asarray(chain.joint_damping_nms_per_rad, dtype=np.float64))
