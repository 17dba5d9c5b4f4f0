"""Hand-built states for each model (shared by the tests), made from absolute link angles."""

from __future__ import annotations

import numpy as np

from biped_constraint_env import kinematics as kin
from biped_constraint_env.hybrid import nb_renumber
from biped_constraint_env.simulator import SimState

OFFSETS = np.array([0.0, 0.5 * np.pi, 0.0, np.pi, 0.0, 0.5 * np.pi])


def q_from_angles(phi):
    """Joint angles (wrapped) from absolute link directions phi (6,)."""
    rel = np.diff(np.concatenate([[0.0], phi])) - OFFSETS
    return np.angle(np.exp(1j * rel))


def model3_state(chain, phi5=0.2, theta0=-0.15, swing_thigh=0.55, heel_z=0.0):
    """Stance foot on its toe (heel up), swing heel on the ground ahead, toe up by phi5 [rad]."""
    phi = np.array([theta0, np.pi / 2 - 0.5, np.pi / 2 - 0.45, 0.0, 0.0, phi5])
    hip = kin.keypoints(chain, q_from_angles(phi))[kin.KEYPOINT_NAMES.index("hip")]
    phi[3] = -np.pi / 2 + swing_thigh  # swing thigh forward (> 0) or back (< 0)
    l3, l4 = chain.links[3].length_m, chain.links[4].length_m
    heel = -0.5 * chain.links[5].length_m
    s4 = (heel_z - hip[1] - l3 * np.sin(phi[3]) - heel * np.sin(phi5)) / l4
    phi[4] = np.arcsin(s4) if swing_thigh > 0 else -np.pi - np.arcsin(s4)  # shank down
    q = q_from_angles(phi)
    assert abs(kin.point_position(chain, q, 5, heel)[1] - heel_z) < 1e-12
    return SimState(0.0, 3, 0, q, np.zeros(6))


def model4_state(params):
    """The model-3 state with the swing foot flat, renumbered (new stance = old swing foot)."""
    s3 = model3_state(params.chain(0), phi5=0.0)
    ch0, ch1 = params.chain(0), params.chain(1)
    q, qd, root = nb_renumber(ch0.packed, ch1.packed, ch0.packed_scalars, s3.q, s3.qd, 0.0)
    assert abs(q[0]) < 1e-12
    q[0] = 0.0
    return SimState(0.0, 4, 1, q, qd, root_y=root)
