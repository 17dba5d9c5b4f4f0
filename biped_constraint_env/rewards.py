"""Reward terms and terminations beyond the simulator's events (shared by both envs)."""

from __future__ import annotations

import numpy as np

TERMINATION_NON_FINITE = "non_finite"
TERMINATION_FALL = "fall"

REWARD_TERMS = ("reward_forward", "reward_alive", "reward_switch", "reward_step", "reward_ctrl")
"""Names of the reward terms in ``info`` (their sum is the reward)."""


def fallen(hip_z, threshold_m: float | None):
    """Whether the hip is below ``threshold_m`` [m] (never when the threshold is None)."""
    if threshold_m is None:
        return hip_z < -np.inf
    return hip_z < threshold_m


def cycle_position(mode: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """4 * steps + (mode - 1): increases by one at every forward model switch."""
    return 4 * steps + (mode - 1)


def reward_terms(
    progress_m,
    dt: float,
    switches,
    steps,
    alive,
    tau: np.ndarray,
    limit: float,
    w_forward: float,
    w_alive: float,
    w_switch: float,
    w_step: float,
    w_ctrl: float,
) -> tuple:
    """The reward terms of one control period, in REWARD_TERMS order (see Rewards).

    Works elementwise on one env (scalars, ``tau`` (5,)) or on n envs (arrays (n,), ``tau``
    (n, 5)) with the same floating-point operations, so both environments agree bit for bit.

    Args:
        progress_m: hip progress [m]. dt: control period [s]. switches: forward model switches
            in the period. steps: walking steps completed in the period. alive: whether the
            period did not end in a termination. tau: applied torques [N m]. limit: torque
            bound [N m]. w_*: the weights.
    """
    if tau.ndim == 1:  # one env: plain floats; sequential sum, as numpy's for 5 elements
        tau_sq = sum(x * x for x in tau.tolist())
    else:
        tau_sq = np.sum(tau * tau, axis=-1)
    return (
        w_forward * progress_m / dt,
        w_alive * alive,
        w_switch * switches,
        w_step * steps,
        -w_ctrl * tau_sq / (limit * limit),
    )


def reward_weights(
    forward: float, alive: float, switch: float, step: float, ctrl: float
) -> tuple[float, ...]:
    """The validated reward weights (each a finite number >= 0), in REWARD_TERMS order."""
    names = (
        "forward_reward_weight",
        "alive_bonus",
        "switch_bonus",
        "step_bonus",
        "ctrl_cost_weight",
    )
    values = (forward, alive, switch, step, ctrl)
    for name, v in zip(names, values, strict=True):
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
    return tuple(float(v) for v in values)


def check_fall_height(fall_hip_height_m) -> float | None:
    """The validated fall height [m] (None: off)."""
    if fall_hip_height_m is None:
        return None
    if not (isinstance(fall_hip_height_m, (int, float)) and np.isfinite(fall_hip_height_m)):
        raise ValueError(
            f"fall_hip_height_m must be a finite number or None, got {fall_hip_height_m!r}"
        )
    return float(fall_hip_height_m)
