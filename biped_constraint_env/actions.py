"""The action: five joint torques [N m], validated the same way in the single and vector env."""

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
