"""Planar forward kinematics: ONE forward pass serves every point, Jacobian and J-dot q-dot.

Conventions (docs/conventions.md): y forward, z up, angles counter-clockwise about +x. The chain is
rooted at the stance toe P = (root_y, 0). Link i has absolute direction
``phi_i = phi_{i-1} + offset_i + q_i`` (offsets 0, pi/2, 0, pi, 0, pi/2), its joint i at
``o_i``, and ``o_{i+1} = o_i + next_i * u(phi_i)`` with ``u(a) = (cos a, sin a)``. A point of
link i is named by its signed offset ``s`` [m] from ``o_i`` along ``u(phi_i)``.

Functions prefixed ``nb_`` are numba-compiled and take the packed arrays of
:attr:`biped_constraint_env.model.ChainModel.packed`; the plain functions are the public,
validated wrappers that take a :class:`~biped_constraint_env.model.ChainModel`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .jit import njit_noalloc
from .model import COL_ANGLE, COL_NEXT, N_LINKS, SC_HEEL0, SC_HEEL5, SC_TOE5, ChainModel

# Keypoints: (link, which offset) pairs, evaluated by nb_keypoints.
KEYPOINT_NAMES: tuple[str, ...] = (
    "stance_toe",
    "stance_heel",
    "stance_ankle",
    "stance_knee",
    "hip",
    "swing_knee",
    "swing_ankle",
    "swing_heel",
    "swing_toe",
)
"""Names of the rows returned by :func:`keypoints`, in order."""
N_KEYPOINTS = len(KEYPOINT_NAMES)


# Columns of the kinematic table K (6, NK) filled by nb_fk: one row per link.
K_PHI, K_COS, K_SIN, K_W, K_AL, K_OY, K_OZ, K_VY, K_VZ, K_AY, K_AZ = range(11)
NK = 11


@njit_noalloc
def nb_fk(ch, q, qd, qdd, root_y, K):
    """The one forward pass: fill the kinematic table K (6, NK) in place.

    Row i holds link i's absolute angle phi_i [rad], cos and sin of it, rate w_i [rad/s],
    acceleration al_i [rad/s^2], and joint i's origin o_i [m], its velocity [m/s] and its
    acceleration [m/s^2] (y, z). The root (stance toe) is at (root_y, 0), at rest.
    """
    a_prev = 0.0
    w_prev = 0.0
    for i in range(N_LINKS):
        ph = a_prev + ch[i, COL_ANGLE] + q[i]
        K[i, K_PHI] = ph
        K[i, K_COS] = np.cos(ph)
        K[i, K_SIN] = np.sin(ph)
        K[i, K_W] = w_prev + qd[i]
        if i == 0:
            K[0, K_OY] = root_y
            K[0, K_OZ] = 0.0
            K[0, K_VY] = 0.0
            K[0, K_VZ] = 0.0
        else:
            ln = ch[i - 1, COL_NEXT]
            ry = ln * K[i - 1, K_COS]
            rz = ln * K[i - 1, K_SIN]
            wp = K[i - 1, K_W]
            K[i, K_OY] = K[i - 1, K_OY] + ry
            K[i, K_OZ] = K[i - 1, K_OZ] + rz
            K[i, K_VY] = K[i - 1, K_VY] - wp * rz
            K[i, K_VZ] = K[i - 1, K_VZ] + wp * ry
        a_prev = ph
        w_prev = K[i, K_W]
    nb_fk_accelerations(ch, qdd, K)


@njit_noalloc
def nb_fk_accelerations(ch, qdd, K):
    """Refill only the accelerations of a table K from :func:`nb_fk` for new joint ``qdd``.

    The angles, rates and positions in K are kept (no trigonometry); :func:`nb_fk` itself
    ends with this pass, so the table equals ``nb_fk(ch, q, qd, qdd, root_y, K)`` bit for bit.
    """
    al_prev = 0.0
    for i in range(N_LINKS):
        K[i, K_AL] = al_prev + qdd[i]
        if i == 0:
            K[0, K_AY] = 0.0
            K[0, K_AZ] = 0.0
        else:
            ln = ch[i - 1, COL_NEXT]
            ry = ln * K[i - 1, K_COS]
            rz = ln * K[i - 1, K_SIN]
            wp = K[i - 1, K_W]
            alp = K[i - 1, K_AL]
            K[i, K_AY] = K[i - 1, K_AY] - alp * rz - wp * wp * ry
            K[i, K_AZ] = K[i - 1, K_AZ] + alp * ry - wp * wp * rz
        al_prev = K[i, K_AL]


@njit_noalloc
def nb_point(K, link, s):
    """(py, pz, vy, vz, ay, az) of the point at offset s [m] on ``link`` (no allocation)."""
    ry = s * K[link, K_COS]
    rz = s * K[link, K_SIN]
    wl = K[link, K_W]
    al = K[link, K_AL]
    return (
        K[link, K_OY] + ry,
        K[link, K_OZ] + rz,
        K[link, K_VY] - wl * rz,
        K[link, K_VZ] + wl * ry,
        K[link, K_AY] - al * rz - wl * wl * ry,
        K[link, K_AZ] + al * ry - wl * wl * rz,
    )


@njit_noalloc
def nb_jacobian_into(K, link, s, jac):
    """Fill jac (2, 6) with the point Jacobian d(point)/dq of offset s on ``link``.

    Column j <= link is z x (p - o_j) = (-(p_z - o_jz), p_y - o_jy); later columns are zero.
    """
    py = K[link, K_OY] + s * K[link, K_COS]
    pz = K[link, K_OZ] + s * K[link, K_SIN]
    for j in range(N_LINKS):
        if j <= link:
            jac[0, j] = -(pz - K[j, K_OZ])
            jac[1, j] = py - K[j, K_OY]
        else:
            jac[0, j] = 0.0
            jac[1, j] = 0.0


@njit(cache=True)
def nb_forward_pass(ch, q, qd, qdd, root_y, base_acc_z):
    """Allocating view of :func:`nb_fk` as separate arrays (for the public API and tests).

    Returns phi (6,), w (6,), al (6,), and o, vo, ao (6, 2): joint-origin position,
    velocity and acceleration (ao with ``base_acc_z`` added to its z component).
    """
    K = np.empty((N_LINKS, NK))
    nb_fk(ch, q, qd, qdd, root_y, K)
    o = np.empty((N_LINKS, 2))
    vo = np.empty((N_LINKS, 2))
    ao = np.empty((N_LINKS, 2))
    o[:, 0] = K[:, K_OY]
    o[:, 1] = K[:, K_OZ]
    vo[:, 0] = K[:, K_VY]
    vo[:, 1] = K[:, K_VZ]
    ao[:, 0] = K[:, K_AY]
    ao[:, 1] = K[:, K_AZ] + base_acc_z
    return K[:, K_PHI].copy(), K[:, K_W].copy(), K[:, K_AL].copy(), o, vo, ao


@njit(cache=True)
def nb_kin_point(ch, q, qd, link, s):
    """(6,) position, velocity and zero-qdd acceleration (J-dot q-dot) of a point."""
    K = np.empty((N_LINKS, NK))
    nb_fk(ch, q, qd, np.zeros(N_LINKS), 0.0, K)
    out = np.empty(6)
    py, pz, vy, vz, ay, az = nb_point(K, link, s)
    out[0] = py
    out[1] = pz
    out[2] = vy
    out[3] = vz
    out[4] = ay
    out[5] = az
    return out


@njit(cache=True)
def nb_point_jacobian(ch, q, link, s):
    """(2, 6) point Jacobian at q (allocating)."""
    K = np.empty((N_LINKS, NK))
    z = np.zeros(N_LINKS)
    nb_fk(ch, q, z, z, 0.0, K)
    jac = np.empty((2, N_LINKS))
    nb_jacobian_into(K, link, s, jac)
    return jac


@njit_noalloc
def nb_keypoints_into(K, sc, out):
    """Fill out (9, 2) with the keypoints named in KEYPOINT_NAMES from the table K."""
    out[0, 0] = K[0, K_OY]
    out[0, 1] = K[0, K_OZ]
    out[1, 0] = K[0, K_OY] + sc[SC_HEEL0] * K[0, K_COS]
    out[1, 1] = K[0, K_OZ] + sc[SC_HEEL0] * K[0, K_SIN]
    for k in range(1, 6):
        out[k + 1, 0] = K[k, K_OY]
        out[k + 1, 1] = K[k, K_OZ]
    out[7, 0] = K[5, K_OY] + sc[SC_HEEL5] * K[5, K_COS]
    out[7, 1] = K[5, K_OZ] + sc[SC_HEEL5] * K[5, K_SIN]
    out[8, 0] = K[5, K_OY] + sc[SC_TOE5] * K[5, K_COS]
    out[8, 1] = K[5, K_OZ] + sc[SC_TOE5] * K[5, K_SIN]


@njit(cache=True)
def nb_keypoints(ch, sc, q, root_y):
    """(9, 2) world positions [m] of the keypoints named in KEYPOINT_NAMES."""
    K = np.empty((N_LINKS, NK))
    z6 = np.zeros(N_LINKS)
    nb_fk(ch, q, z6, z6, root_y, K)
    out = np.empty((9, 2))
    nb_keypoints_into(K, sc, out)
    return out


@njit_noalloc
def nb_hip_kinematics(ch, q, qd, root_y, K):
    """(y, z, vy, vz) of the hip (joint 3) [m, m/s], using K (6, NK) as scratch.

    The accelerations left in K are those of qdd = qd (not meaningful); only positions and
    velocities are read.
    """
    nb_fk(ch, q, qd, qd, root_y, K)
    return K[3, K_OY], K[3, K_OZ], K[3, K_VY], K[3, K_VZ]


def _vec6(name: str, x: object) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (N_LINKS,):
        raise ValueError(f"{name} must have shape ({N_LINKS},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {a}")
    return a


def _link_offset(link: int, s: float) -> tuple[int, float]:
    if not 0 <= int(link) < N_LINKS:
        raise ValueError(f"link must be in 0..{N_LINKS - 1}, got {link!r}")
    if not np.isfinite(s):
        raise ValueError(f"offset must be finite, got {s!r}")
    return int(link), float(s)


def link_angles(q: np.ndarray) -> np.ndarray:
    """(6,) absolute link directions phi_i [rad] (docs/conventions.md) for angles q (6,) [rad]."""
    q = _vec6("q", q)
    offsets = np.array([0.0, 0.5 * np.pi, 0.0, np.pi, 0.0, 0.5 * np.pi])
    return np.cumsum(offsets + q)


def point_position(chain: ChainModel, q, link: int, s: float, root_y: float = 0.0) -> np.ndarray:
    """(2,) world position [m] of the point at offset ``s`` [m] along ``link``."""
    link, s = _link_offset(link, s)
    p = nb_kin_point(chain.packed, _vec6("q", q), np.zeros(N_LINKS), link, s)[:2]
    return p + np.array([float(root_y), 0.0])


def point_velocity(chain: ChainModel, q, qd, link: int, s: float) -> np.ndarray:
    """(2,) world velocity [m/s] of a link point (the root at rest)."""
    link, s = _link_offset(link, s)
    return nb_kin_point(chain.packed, _vec6("q", q), _vec6("qd", qd), link, s)[2:4]


def point_jacobian(chain: ChainModel, q, link: int, s: float) -> np.ndarray:
    """(2, 6) point Jacobian d p / d q [m/rad] of the point at offset ``s`` on ``link``."""
    link, s = _link_offset(link, s)
    return nb_point_jacobian(chain.packed, _vec6("q", q), link, s)


def point_bias_acceleration(chain: ChainModel, q, qd, link: int, s: float) -> np.ndarray:
    """(2,) exact J-dot q-dot [m/s^2]: the point's acceleration at zero joint acceleration."""
    link, s = _link_offset(link, s)
    return nb_kin_point(chain.packed, _vec6("q", q), _vec6("qd", qd), link, s)[4:6]


def point_bias_acceleration_fd(chain: ChainModel, q, qd, link: int, s: float, h: float):
    """(2,) the paper's backward-difference J-dot q-dot (eq. 7-8) over one sample h [s].

    ``(J(q) - J(q - h qd)) qd / h``: q - h qd is the previous sample's posture under the
    semi-implicit Euler update. It differs from the exact value by O(h).
    """
    q = _vec6("q", q)
    qd = _vec6("qd", qd)
    return (point_jacobian(chain, q, link, s) - point_jacobian(chain, q - h * qd, link, s)) @ qd / h


def keypoints(chain: ChainModel, q, root_y: float = 0.0) -> np.ndarray:
    """(9, 2) world positions [m] of the keypoints in :data:`KEYPOINT_NAMES` order."""
    return nb_keypoints(chain.packed, chain.packed_scalars, _vec6("q", q), float(root_y))


@njit(cache=True)
def nb_swing_ankle_vy(CHS, Q, QD, IST, out):
    """out[i]: the forward velocity [m/s] of row i's swing ankle (joint 5).

    CHS (n, 2, 6, 6): each row's packed robot in both numberings; IST[i, 1] the stance side.
    """
    K = np.empty((N_LINKS, NK))
    z = np.zeros(N_LINKS)
    for i in range(Q.shape[0]):
        nb_fk(CHS[i, IST[i, 1]], Q[i], QD[i], z, 0.0, K)
        out[i] = K[5, K_VY]
