"""The action mappings, validated the same way in the single and vector env.

* **Torques** (``action="torque"``): five joint torques [N m], held over the control period.
* **PD targets** (``action="pd"``): five joint targets, held over the control period; the PD
  law ``clip(Kp (target - q) + Kd (rate - q-dot), -limit, limit)`` is evaluated at every
  physics step of ``pd_dt`` inside it (decimation, as legged-robot RL does: the policy
  decides every ``dt``, the joint servo runs every ``pd_dt``), in compiled code
  (:func:`nb_pd_torques`, called by the control period). ``pd_dt = dt`` holds the PD torque
  over the period (the law of earlier versions of the env).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .jit import njit_noalloc
from .model import N_ACTUATED
from .validation import check_choice, check_real

TORQUE_LIMIT_NM = 150.0
"""Default action bound [N m] (>= 120 so that Table 2 fits)."""
TORQUE_LIMIT_MIN_NM, TORQUE_LIMIT_MAX_NM = 1e-3, 1e6
"""Accepted range of ``torque_limit_nm`` [N m] (the control cost divides by its square)."""


PD_KP = np.array([60.0, 150.0, 150.0, 80.0, 30.0])
"""Proportional gains of the PD-target actions, joints 1..5 [N m / rad] (times
``pd_gain_scale``): a target 1 rad away asks for about the torques the model-based teacher
uses at most (a mid-stride start needs 150 N m at the swing hip at once)."""
PD_KD = np.array([3.0, 8.0, 8.0, 4.0, 1.0])
"""Derivative gains [N m s / rad] (times the square root of ``pd_gain_scale``; on top of
the joints' own damping of 10)."""
PD_DT_S = 0.005
"""Default physics step of the PD law [s] (``pd_dt``): 200 Hz, the walking task's step; a
control period of 20 ms applies its targets through four PD updates."""
PCFG_NSUB, PCFG_LIMIT, PCFG_RANGE, PCFG_KP, PCFG_KD = 0, 1, 2, 3, 3 + N_ACTUATED
"""Entries of :func:`pd_config`'s array: PD updates per period (0: torque actions), the
torque bound [N m], the targets' half-range [rad], Kp (5), Kd (5)."""


MIN_PD_DT_S = 5e-4
"""Shortest PD update period accepted [s] (each update is at least one integration step)."""


def check_pd_dt(pd_dt, dt: float) -> int:
    """PD updates per control period for ``pd_dt`` [s] (None: :data:`PD_DT_S`, at most dt).

    ``dt`` must be a whole multiple of ``pd_dt``.
    """
    if pd_dt is None:
        pd_dt = min(PD_DT_S, dt)
    pd_dt = check_real("pd_dt", pd_dt, min(MIN_PD_DT_S, dt), dt, unit=" [s]")
    n = round(dt / pd_dt)
    if n < 1 or abs(n * pd_dt - dt) > 1e-9 * dt:
        raise ValueError(f"pd_dt must divide the control period dt = {dt} s, got {pd_dt}")
    return int(n)


def pd_config(
    n_sub: int, limit: float, pd_range: float, kp: np.ndarray, kd: np.ndarray
) -> np.ndarray:
    """The PD mapping as one array for the compiled period (``n_sub`` 0: torque actions).

    An action a in [-1, 1]^5 sets the targets ``base + pd_range * a`` [rad] (``base``: the
    pose and offset, or the reference's pose at the clock).
    """
    return np.array([float(n_sub), float(limit), float(pd_range), *kp, *kd], dtype=np.float64)


TORQUE_ACTIONS = pd_config(0, 0.0, 0.0, np.zeros(N_ACTUATED), np.zeros(N_ACTUATED))
"""The :func:`pd_config` of torque actions (no PD law)."""


@njit_noalloc
def nb_pd_targets(base, action, pcfg, target) -> None:
    """The PD targets: target (5,) = base + pd_range * clip(action, -1, 1) [rad]."""
    r = pcfg[PCFG_RANGE]
    for j in range(N_ACTUATED):
        target[j] = base[j] + r * min(max(action[j], -1.0), 1.0)


@njit_noalloc
def nb_pd_torques(target, rate, q, qd, pcfg, tau) -> None:
    """The PD torques: tau (5,) = clip(Kp (target - q[1:]) + Kd (rate - qd[1:]), +-limit)."""
    limit = pcfg[PCFG_LIMIT]
    for j in range(N_ACTUATED):
        x = pcfg[PCFG_KP + j] * (target[j] - q[j + 1]) + pcfg[PCFG_KD + j] * (rate[j] - qd[j + 1])
        tau[j] = min(max(x, -limit), limit)


PD_BOUND = "PD-target bound"
"""``bound`` of :func:`validate_actions` for PD-target actions (limit 1, no unit)."""


def validate_actions(
    actions: Any, limit: float, out_of_range: str, bound: str = "torque limit"
) -> np.ndarray:
    """(..., 5) float64 torques [N m]; ValueError on NaN/inf/shape/dtype/range (as documented).

    ``bound`` names the limit in the messages (:data:`PD_BOUND` for PD-target actions).
    """
    a = actions if isinstance(actions, np.ndarray) else np.asarray(actions)
    if a.shape[-1:] != (N_ACTUATED,):
        raise ValueError(f"action must have shape ({N_ACTUATED},), got {a.shape}")
    if a.dtype.kind not in "fiu":
        raise ValueError(f"action must be real numbers, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if a.ndim == 1:  # a comparison with NaN is False, so this screens NaN, inf and range
        inside = all(-limit <= x <= limit for x in a.tolist())
    else:
        inside = np.abs(a).max() <= limit  # NaN propagates through max
    if not inside:
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a}")
        if out_of_range == "raise":
            unit = " N m" if bound == "torque limit" else ""
            raise ValueError(f"action {a} exceeds the {bound} +-{limit}{unit}")
        a = np.clip(a, -limit, limit)
    return a


def validate_action(
    action: Any, limit: float, out_of_range: str, bound: str = "torque limit"
) -> np.ndarray:
    """(5,) float64 torques [N m] from one action (see :func:`validate_actions`)."""
    a = action if isinstance(action, np.ndarray) else np.asarray(action)
    if a.shape != (N_ACTUATED,):
        raise ValueError(f"action must have shape ({N_ACTUATED},), got {a.shape}")
    if a.dtype.kind == "f":  # the common case, checked with Python floats (fastest for 5)
        a64 = a.astype(np.float64)
        if all(-limit <= x <= limit for x in a64.tolist()):  # False for NaN: screens it too
            return a64
    return validate_actions(a, limit, out_of_range, bound)


def check_action_settings(torque_limit_nm: float, out_of_range: str) -> tuple[float, str]:
    """The validated torque limit [N m] and out-of-range policy of an env."""
    limit = check_real(
        "torque_limit_nm", torque_limit_nm, TORQUE_LIMIT_MIN_NM, TORQUE_LIMIT_MAX_NM, unit=" [N m]"
    )
    return limit, check_choice("out_of_range", out_of_range, ("clip", "raise"))


def action_config(limit: float, out_of_range: str) -> np.ndarray:
    """[limit, clip] for :func:`nb_check_torques`: the bound [N m], 1.0 to clip (0.0: raise)."""
    return np.array([limit, 1.0 if out_of_range == "clip" else 0.0])


@njit_noalloc
def nb_check_torques(ACT, acfg) -> int:
    """The compiled twin of :func:`validate_actions` on float64 actions (n, 5), in place.

    Returns 0 when every torque is finite and, with ``acfg[1] == 1``, clips it to
    ``[-acfg[0], acfg[0]]``; returns 1 (the caller raises through :func:`validate_action`)
    on a NaN or inf, or on a torque beyond the bound when clipping is off.
    """
    limit = acfg[0]
    clip = acfg[1] != 0.0
    for i in range(ACT.shape[0]):
        for j in range(ACT.shape[1]):
            x = ACT[i, j]
            if not np.isfinite(x):
                return 1
            if x > limit or x < -limit:
                if not clip:
                    return 1
                ACT[i, j] = min(max(x, -limit), limit)
    return 0
