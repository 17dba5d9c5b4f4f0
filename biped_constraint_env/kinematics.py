"""Planar forward kinematics: ONE forward pass serves every point, Jacobian and J-dot q-dot.

Conventions (MODEL.md): y forward, z up, angles counter-clockwise about +x. The chain is
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


@njit(cache=True)
def nb_forward_pass(ch, q, qd, qdd, root_y, base_acc_z):
    """Absolute angles, rates, accelerations and joint-origin kinematics of every link.

    Args:
        ch: (6, 6) packed chain.
        q, qd, qdd: (6,) joint angles [rad], rates [rad/s], accelerations [rad/s^2].
        root_y: world y of the chain root (stance toe) [m]; the root is at rest.
        base_acc_z: upward acceleration given to the root [m/s^2] (g for the RNEA gravity trick,
            0 for true kinematics).

    Returns:
        phi (6,), w (6,), al (6,): absolute angle [rad], rate [rad/s], acceleration [rad/s^2].
        o, vo, ao: (6, 2) position [m], velocity [m/s] and acceleration [m/s^2] of joint i.
    """
    phi = np.empty(N_LINKS)
    w = np.empty(N_LINKS)
    al = np.empty(N_LINKS)
    o = np.zeros((N_LINKS, 2))
    vo = np.zeros((N_LINKS, 2))
    ao = np.zeros((N_LINKS, 2))
    o[0, 0] = root_y
    ao[0, 1] = base_acc_z
    a_prev = 0.0
    w_prev = 0.0
    al_prev = 0.0
    for i in range(N_LINKS):
        phi[i] = a_prev + ch[i, COL_ANGLE] + q[i]
        w[i] = w_prev + qd[i]
        al[i] = al_prev + qdd[i]
        if i > 0:
            ry = ch[i - 1, COL_NEXT] * np.cos(phi[i - 1])
            rz = ch[i - 1, COL_NEXT] * np.sin(phi[i - 1])
            wp = w[i - 1]
            o[i, 0] = o[i - 1, 0] + ry
            o[i, 1] = o[i - 1, 1] + rz
            vo[i, 0] = vo[i - 1, 0] - wp * rz
            vo[i, 1] = vo[i - 1, 1] + wp * ry
            ao[i, 0] = ao[i - 1, 0] - al[i - 1] * rz - wp * wp * ry
            ao[i, 1] = ao[i - 1, 1] + al[i - 1] * ry - wp * wp * rz
        a_prev = phi[i]
        w_prev = w[i]
        al_prev = al[i]
    return phi, w, al, o, vo, ao


@njit(cache=True)
def nb_point_kinematics(phi, w, al, o, vo, ao, link, s):
    """Position, velocity and acceleration (each (2,)) of the point at offset s [m] on a link."""
    c = np.cos(phi[link])
    sn = np.sin(phi[link])
    ry = s * c
    rz = s * sn
    wl = w[link]
    p = np.empty(2)
    v = np.empty(2)
    a = np.empty(2)
    p[0] = o[link, 0] + ry
    p[1] = o[link, 1] + rz
    v[0] = vo[link, 0] - wl * rz
    v[1] = vo[link, 1] + wl * ry
    a[0] = ao[link, 0] - al[link] * rz - wl * wl * ry
    a[1] = ao[link, 1] + al[link] * ry - wl * wl * rz
    return p, v, a


@njit(cache=True)
def nb_point_jacobian(phi, o, link, s):
    """(2, 6) Jacobian d(point)/dq of the point at offset s [m] on ``link``.

    Column j <= link is z x (p - o_j) = (-(p_z - o_jz), p_y - o_jy); later columns are zero.
    """
    py = o[link, 0] + s * np.cos(phi[link])
    pz = o[link, 1] + s * np.sin(phi[link])
    jac = np.zeros((2, N_LINKS))
    for j in range(link + 1):
        jac[0, j] = -(pz - o[j, 1])
        jac[1, j] = py - o[j, 0]
    return jac


@njit(cache=True)
def nb_keypoints(ch, sc, q, root_y):
    """(9, 2) world positions [m] of the keypoints named in KEYPOINT_NAMES."""
    z6 = np.zeros(N_LINKS)
    phi, w, al, o, vo, ao = nb_forward_pass(ch, q, z6, z6, root_y, 0.0)
    out = np.empty((9, 2))
    out[0] = o[0]
    out[1, 0] = o[0, 0] + sc[SC_HEEL0] * np.cos(phi[0])
    out[1, 1] = o[0, 1] + sc[SC_HEEL0] * np.sin(phi[0])
    for k in range(1, 6):
        out[k + 1] = o[k]
    out[7, 0] = o[5, 0] + sc[SC_HEEL5] * np.cos(phi[5])
    out[7, 1] = o[5, 1] + sc[SC_HEEL5] * np.sin(phi[5])
    out[8, 0] = o[5, 0] + sc[SC_TOE5] * np.cos(phi[5])
    out[8, 1] = o[5, 1] + sc[SC_TOE5] * np.sin(phi[5])
    return out


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
    """(6,) absolute link directions phi_i [rad] (MODEL.md) for joint angles q (6,) [rad]."""
    q = _vec6("q", q)
    offsets = np.array([0.0, 0.5 * np.pi, 0.0, np.pi, 0.0, 0.5 * np.pi])
    return np.cumsum(offsets + q)


def point_position(chain: ChainModel, q, link: int, s: float, root_y: float = 0.0) -> np.ndarray:
    """(2,) world position [m] of the point at offset ``s`` [m] along ``link``."""
    link, s = _link_offset(link, s)
    z = np.zeros(N_LINKS)
    phi, w, al, o, vo, ao = nb_forward_pass(chain.packed, _vec6("q", q), z, z, float(root_y), 0.0)
    return nb_point_kinematics(phi, w, al, o, vo, ao, link, s)[0]


def point_velocity(chain: ChainModel, q, qd, link: int, s: float) -> np.ndarray:
    """(2,) world velocity [m/s] of a link point (the root at rest)."""
    link, s = _link_offset(link, s)
    z = np.zeros(N_LINKS)
    out = nb_forward_pass(chain.packed, _vec6("q", q), _vec6("qd", qd), z, 0.0, 0.0)
    return nb_point_kinematics(*out, link, s)[1]


def point_jacobian(chain: ChainModel, q, link: int, s: float) -> np.ndarray:
    """(2, 6) point Jacobian d p / d q [m/rad] of the point at offset ``s`` on ``link``."""
    link, s = _link_offset(link, s)
    z = np.zeros(N_LINKS)
    phi, w, al, o, vo, ao = nb_forward_pass(chain.packed, _vec6("q", q), z, z, 0.0, 0.0)
    return nb_point_jacobian(phi, o, link, s)


def point_bias_acceleration(chain: ChainModel, q, qd, link: int, s: float) -> np.ndarray:
    """(2,) exact J-dot q-dot [m/s^2]: the point's acceleration at zero joint acceleration."""
    link, s = _link_offset(link, s)
    z = np.zeros(N_LINKS)
    out = nb_forward_pass(chain.packed, _vec6("q", q), _vec6("qd", qd), z, 0.0, 0.0)
    return nb_point_kinematics(*out, link, s)[2]


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
