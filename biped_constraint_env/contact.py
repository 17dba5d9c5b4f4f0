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

from .jit import njit_noalloc
from .kinematics import nb_jacobian_into, nb_point
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


@njit_noalloc
def nb_slip_sign(v_slip, eps):
    """Regularised sign of the sliding speed v_slip [m/s]: v / sqrt(v^2 + eps^2)."""
    return v_slip / np.sqrt(v_slip * v_slip + eps * eps)


@njit_noalloc
def nb_contact_rows(K, Kp, qd, s_off, eps, fd_h, jac, jacp):
    """Rows of one point contact at offset ``s_off`` [m] on link 5.

    Args:
        K: kinematic table of the forward pass at (q, qd, qdd = 0).
        Kp: table at the previous sample q - fd_h qd (read only when fd_h > 0).
        qd: (6,) joint rates. eps: slip regularisation [m/s].
        fd_h: 0 for the exact J-dot q-dot, else the sample time [s] of the paper's difference.
        jac, jacp: (2, 6) outputs: the point Jacobian at q (and at the previous sample).

    Returns:
        gamma: the constraint bias -Jdot_z qd [m/s^2]; C_q = jac[1] (= J_c).
        slip_sign: s, so that the generalised force per unit f_n is jac[1] - K s jac[0].
    """
    nb_jacobian_into(K, 5, s_off, jac)
    v_slip = 0.0
    for j in range(6):
        v_slip += jac[0, j] * qd[j]
    sg = nb_slip_sign(v_slip, eps)
    if fd_h > 0.0:
        nb_jacobian_into(Kp, 5, s_off, jacp)
        gamma = 0.0
        for j in range(6):
            gamma -= (jac[1, j] - jacp[1, j]) * qd[j] / fd_h
    else:
        gamma = -nb_point(K, 5, s_off)[5]
    return gamma, sg
