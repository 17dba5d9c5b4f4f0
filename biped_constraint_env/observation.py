"""The 24-entry observation, filled by one compiled function for the single and vector env."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from numba import njit

from .clock import PHASE_HIGH, PHASE_LOW, PHASE_NAMES
from .command import COMMAND_OBS_HIGH, COMMAND_OBS_LOW
from .hybrid import nb_wrap
from .jit import njit_noalloc
from .kinematics import NK, nb_hip_kinematics
from .model import N_LINKS

OBS_RATE_LIMIT_RAD_S = 1e3
"""Bound of the joint-rate observations [rad/s] (values beyond are clipped; with the damping of
10 N m s/rad and 150 N m torques, steady rates stay below ~50 rad/s)."""
OBS_LENGTH_LIMIT_M = 10.0
"""Bound of the hip-position observations [m] (the legs are 3 m long)."""
OBS_SPEED_LIMIT_M_S = 1e3
"""Bound of the hip-velocity observations [m/s]."""
OBS_FORCE_LIMIT_N = 1e5
"""Bound of the contact-force observations [N] (the robot weighs 49 N)."""
OBS_DIM = 24
OBS_NAMES: tuple[str, ...] = (
    "theta0",
    "q1",
    "q2",
    "q3",
    "q4",
    "q5",
    "theta0_dot",
    "q1_dot",
    "q2_dot",
    "q3_dot",
    "q4_dot",
    "q5_dot",
    "hip_y_rel_stance_toe",
    "hip_z",
    "hip_vy",
    "hip_vz",
    "stance_side",
    "mode_1",
    "mode_2",
    "mode_3",
    "mode_4",
    "f_stance_toe",
    "f_stance_heel",
    "f_contact_normal",
)
"""Observation entries, in order (see the env docstring's table)."""
OBS_Q, OBS_QD, OBS_HIP = slice(0, 6), slice(6, 12), slice(12, 16)
"""Where the observation holds theta0, q1..q5; their rates; the hip's (y, z, vy, vz)."""
OBS_SIDE, OBS_MODE, OBS_FORCES = 16, slice(17, 21), slice(21, 24)
"""The stance leg; the model one-hot; the contact forces (toe, heel, point contact)."""


def _obs_bounds() -> tuple[np.ndarray, np.ndarray]:
    high = np.empty(OBS_DIM)
    high[:6] = np.pi
    high[6:12] = OBS_RATE_LIMIT_RAD_S
    high[12:14] = OBS_LENGTH_LIMIT_M
    high[14:16] = OBS_SPEED_LIMIT_M_S
    high[16:21] = 1.0
    high[21:24] = OBS_FORCE_LIMIT_N
    low = -high
    low[16:21] = 0.0
    return low, high


OBS_LOW, OBS_HIGH = _obs_bounds()


@njit_noalloc
def nb_observe_row(chs, scs, q, qd, ist, fst, forces, obs, hip, low, high, K):
    """Fill one environment's obs (24,), clipped to [low, high], and hip (4: y, z, vy, vz).

    K: (6, NK) kinematics workspace.
    """
    side = ist[1]
    mode = ist[0]
    hy, hz, hvy, hvz = nb_hip_kinematics(chs[side], q, qd, fst[1], K)
    hip[0] = hy
    hip[1] = hz
    hip[2] = hvy
    hip[3] = hvz
    for j in range(6):
        obs[j] = nb_wrap(q[j])  # angles, so wrapped to (-pi, pi]
        obs[6 + j] = qd[j]
    obs[12] = hy - fst[1]
    obs[13] = hz
    obs[14] = hvy
    obs[15] = hvz
    obs[16] = side
    for m in range(4):
        obs[17 + m] = 1.0 if mode == m + 1 else 0.0
    obs[21] = forces[0]
    obs[22] = forces[1]
    obs[23] = forces[2]
    for j in range(obs.shape[0]):
        obs[j] = min(max(obs[j], low[j]), high[j])


@njit(cache=True)
def nb_observe(CHS, SCS, Q, QD, IST, FST, FORCES, OBS, HIP, low, high):
    """Fill OBS (n, 24), clipped to [low, high], and HIP (n, 4: hip y, z, vy, vz).

    CHS (n, 2, 6, 6), SCS (n, 2, 8): each row's packed robot.
    """
    K = np.empty((N_LINKS, NK))
    for i in range(Q.shape[0]):
        nb_observe_row(
            CHS[i], SCS[i], Q[i], QD[i], IST[i], FST[i], FORCES[i], OBS[i], HIP[i], low, high, K
        )


@dataclass(frozen=True)
class ObservationBlock:
    """Entries appended to the 24 base entries: their names, bounds, and the core's values.

    ``features(core)`` gives the (n, k) block after a period or a reset; ``needs_clock``:
    whether it reads the contact clock (the env then keeps one).
    """

    names: tuple[str, ...]
    low: np.ndarray
    high: np.ndarray
    features: Callable[[Any], np.ndarray]
    needs_clock: bool = False


GRAVITY_NAMES = ("gravity_y", "gravity_z")
"""The ``"gravity"`` block: the direction of gravity in the ground's frame (a unit vector,
(-sin a, -cos a) on a slope of a rising forward; (0, -1) on flat ground), what legged-robot RL
observes from an IMU as the projected gravity. Without it a slope shows only in the motion:
at rest the observation on a slope equals the one on flat ground."""


def gravity_features(core) -> np.ndarray:
    """(n, 2): each row's gravity direction in the ground's frame (:data:`GRAVITY_NAMES`)."""
    a = np.array([p.slope_rad for p in core.perturb.params])
    return np.stack([-np.sin(a), -np.cos(a)], axis=1)


OBSERVATION_BLOCKS: dict[str, ObservationBlock] = {
    "phase": ObservationBlock(PHASE_NAMES, PHASE_LOW, PHASE_HIGH,
                              lambda core: core.clock.features(), needs_clock=True),
    "gravity": ObservationBlock(GRAVITY_NAMES, -np.ones(2), np.ones(2), gravity_features),
    "command": ObservationBlock(("command_m_s",), COMMAND_OBS_LOW, COMMAND_OBS_HIGH,
                                lambda core: core.commands.features()),
}  # fmt: skip
"""The observation's blocks by name, in the order they follow the base entries. A new block is
one entry here (``observation=[name]`` appends it); "command" comes with the command option."""


def observation_names(blocks: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The observation's entry names, in order: :data:`OBS_NAMES`, then each block's."""
    return OBS_NAMES + tuple(n for b in blocks for n in OBSERVATION_BLOCKS[b].names)


def observation_space(blocks: tuple[str, ...] = ()) -> spaces.Box:
    """The observation Box: the base entries, then each block of ``blocks``.

    Bounds in the env docstring's table; the blocks' in :data:`OBSERVATION_BLOCKS`.
    """
    low = [OBS_LOW, *(OBSERVATION_BLOCKS[b].low for b in blocks)]
    high = [OBS_HIGH, *(OBSERVATION_BLOCKS[b].high for b in blocks)]
    return spaces.Box(np.concatenate(low), np.concatenate(high), dtype=np.float64)
