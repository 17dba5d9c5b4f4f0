"""Reward terms and terminations beyond the simulator's events (shared by both envs)."""

from __future__ import annotations

import numpy as np

from .jit import njit_noalloc
from .validation import check_real

TERMINATION_NON_FINITE = "non_finite"
TERMINATION_FALL = "fall"

REWARD_TERMS = ("reward_forward", "reward_alive", "reward_switch", "reward_step", "reward_ctrl")
"""Names of the reward terms in ``info`` (their sum is the reward)."""


REWARD_WEIGHT_MAX = 1e6
"""Largest accepted reward weight."""

CFG_FORWARD, CFG_ALIVE, CFG_SWITCH, CFG_STEP, CFG_CTRL, CFG_LIMIT, CFG_FALL = range(7)
"""Entries of :func:`reward_config`'s array."""


def reward_config(
    weights: tuple[float, ...], torque_limit_nm: float, fall_hip_height_m: float | None
) -> np.ndarray:
    """The reward settings as one array, for :func:`nb_reward_terms`.

    The weights (REWARD_TERMS order), the torque bound [N m] and the fall height [m] (-inf:
    off), indexed by the CFG_* constants.
    """
    fall = -np.inf if fall_hip_height_m is None else fall_hip_height_m
    return np.array([*weights, torque_limit_nm, fall], dtype=np.float64)


@njit_noalloc
def nb_fallen(hip_z: float, cfg: np.ndarray) -> bool:
    """Whether the hip is below the fall height (never when it is off: -inf)."""
    return hip_z < cfg[CFG_FALL]


@njit_noalloc
def nb_cycle_position(mode: int, steps: int) -> int:
    """4 * steps + (mode - 1): increases by one at every forward model switch."""
    return 4 * steps + (mode - 1)


@njit_noalloc
def nb_reward_terms(progress_m, dt, switches, steps, alive, tau, cfg, out, tau_sq=-1.0):
    """The reward terms of one control period, and their sum (see the env docstring, Rewards).

    Writes the terms into ``out[:5]`` (REWARD_TERMS order) and their sum into ``out[5]``.

    Args:
        progress_m: hip progress [m]. dt: control period [s]. switches: forward model switches
            in the period. steps: walking steps completed in the period. alive: whether the
            period did not end in a termination. tau: (5,) applied torques [N m]. cfg:
            :func:`reward_config`. out: (6,) output. tau_sq: sum(tau^2) [N^2 m^2] when the
            torques varied over the period (its time mean; PD at the physics rate), else < 0:
            sum(tau^2) of ``tau``.
    """
    if tau_sq < 0.0:
        tau_sq = 0.0
        for j in range(tau.shape[0]):
            tau_sq += tau[j] * tau[j]
    limit = cfg[CFG_LIMIT]
    out[0] = cfg[CFG_FORWARD] * progress_m / dt
    out[1] = cfg[CFG_ALIVE] * (1.0 if alive else 0.0)
    out[2] = cfg[CFG_SWITCH] * switches
    out[3] = cfg[CFG_STEP] * steps
    out[4] = -cfg[CFG_CTRL] * tau_sq / (limit * limit)
    out[5] = out[0] + out[1] + out[2] + out[3] + out[4]


def reward_weights(
    forward: float, alive: float, switch: float, step: float, ctrl: float
) -> tuple[float, ...]:
    """The validated reward weights (each in [0, REWARD_WEIGHT_MAX]), in REWARD_TERMS order."""
    names = (
        "forward_reward_weight",
        "alive_bonus",
        "switch_bonus",
        "step_bonus",
        "ctrl_cost_weight",
    )
    values = (forward, alive, switch, step, ctrl)
    return tuple(
        check_real(n, v, 0.0, REWARD_WEIGHT_MAX) for n, v in zip(names, values, strict=True)
    )


def check_fall_height(fall_hip_height_m) -> float | None:
    """The validated fall height [m] (None: off)."""
    if fall_hip_height_m is None:
        return None
    return check_real("fall_hip_height_m", fall_hip_height_m, -10.0, 10.0, unit=" [m]")
