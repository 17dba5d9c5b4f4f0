"""Ground contacts as constraint rows (paper eq. 1-9).

Two kinds of contact, both planar:

- the *flat foot* (models 1 and 4): the stance foot is part of the ground, so ``theta0`` is
  not an unknown (the paper leaves Link-0 out of the equations, eq. 15 and 30);
- the *point contact* (models 3 and 4): one foot end held at ``z = 0`` by the normal force
  ``f_n`` (the Lagrange multiplier), free to slide along the ground against the friction
  ``f_t = K f_n`` that opposes its sliding velocity (paper eq. 4).

The friction direction ``rdot / ||rdot||`` is discontinuous at zero slip; it is regularised
as ``v / sqrt(v^2 + eps^2)`` with ``eps = friction_velocity_eps`` [m/s], so the friction
fades to zero at zero slip. Like the paper's law, it is purely kinetic: there is no stiction.

The constraint row is ``C_q = J_z`` (the point's vertical Jacobian row), the generalised
contact force is ``(J_c - K s J_t)^T f_n`` with ``J_c = J_z``, ``J_t = J_y`` and ``s`` the
regularised slip sign, and the constraint bias is ``gamma = -Jdot_z qd`` (exact: the point's
vertical acceleration at zero joint acceleration; or the paper's backward difference).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

from .kinematics import nb_point_jacobian, nb_point_kinematics
from .model import SC_HEEL5, SC_TOE5


class FootEnd(IntEnum):
    """Which end of the swing foot (link 5) a point contact holds."""

    HEEL = SC_HEEL5
    TOE = SC_TOE5


@dataclass(frozen=True)
class PointContact:
    """A point of the swing foot (link 5) held at z = 0, sliding with friction K f_n."""

    end: FootEnd

    @property
    def link(self) -> int:
        """Link index carrying the contact point (always the swing foot, 5)."""
        return 5


SWING_HEEL = PointContact(FootEnd.HEEL)
"""Model 3's contact: the swing heel (point E_r of the paper)."""
OLD_STANCE_TOE = PointContact(FootEnd.TOE)
"""Model 4's contact: the old stance toe, the renumbered chain's swing toe (point E_f)."""


@njit(cache=True)
def nb_slip_sign(v_slip, eps):
    """Regularised sign of the sliding speed v_slip [m/s]: v / sqrt(v^2 + eps^2)."""
    return v_slip / np.sqrt(v_slip * v_slip + eps * eps)


@njit(cache=True)
def nb_contact_rows(kin, q, qd, s_off, friction, eps, fd_h, fk_prev):
    """Rows of one point contact at offset ``s_off`` on link 5.

    Args:
        kin: the forward pass tuple (phi, w, al, o, vo, ao) at (q, qd, qdd = 0, g = 0).
        q, qd: (6,) state. s_off: offset of the point along link 5 [m].
        friction: K. eps: slip regularisation [m/s].
        fd_h: 0 for the exact J-dot q-dot, else the sample time [s] of the paper's difference.
        fk_prev: forward pass at q - fd_h * qd (used only when fd_h > 0).

    Returns:
        c_row (6,): J_z, the constraint Jacobian row C_q.
        force_row (6,): (J_c - K s J_t), the generalised force per unit f_n.
        gamma: constraint bias -Jdot_z qd [m/s^2].
        slip_sign: s.
    """
    phi, w, al, o, vo, ao = kin
    jac = nb_point_jacobian(phi, o, 5, s_off)
    v_slip = 0.0
    for j in range(6):
        v_slip += jac[0, j] * qd[j]
    sg = nb_slip_sign(v_slip, eps)
    force_row = jac[1] - friction * sg * jac[0]
    if fd_h > 0.0:
        jp = nb_point_jacobian(fk_prev[0], fk_prev[3], 5, s_off)
        gamma = 0.0
        for j in range(6):
            gamma -= (jac[1, j] - jp[1, j]) * qd[j] / fd_h
    else:
        gamma = -nb_point_kinematics(phi, w, al, o, vo, ao, 5, s_off)[2][1]
    return jac[1].copy(), force_row, gamma, sg
