"""The contact clock of N environments, and the phase observation it gives (``phase_obs``).

Per environment: whether a start at rest is still walking its first step, whether a start near
rest is still in its first contact phase (no model switch since the start: the ``opening``
phase, the sway before the first step), the model, and the control periods since that model
began (restarting at every model switch). With
``phase_obs=True`` the observation appends :data:`PHASE_NAMES`: the first-step flag (1 from a
start at rest until the first step completes) and the time in the current model [s], counted
in control periods and clipped to :data:`MODEL_TIME_MAX_S`. Both envs keep it with this class,
so the single and the batched env observe the same numbers.

Why: a controller that starts from rest moves differently in its first step than in the gait
(biped_constraint_env's model-based teacher has gains of its own until the legs first swap);
without the flag, states of the first step and of the gait can look alike and a network that
imitates the teacher cannot tell which it is in.
"""

from __future__ import annotations

import numpy as np

AT_REST_RATE_RAD_S = 1e-3
"""A model-1 start whose joint rates are all below this [rad/s] is a start at rest."""
NEAR_REST_RATE_RAD_S = 0.6
"""A model-1 start whose joint rates are all at most this [rad/s] is a start near rest: its
first contact phase is the ``opening`` phase (the nudge start's fastest rate; the slowest
flat-foot stride starts)."""
MODEL_TIME_MAX_S = 2.0
"""The observed time in the current model is clipped to this [s]."""


def near_rest(modes, qd) -> np.ndarray:
    """Which states are starts near rest: model 1, every joint rate <= NEAR_REST_RATE_RAD_S.

    Shapes as :func:`at_rest`'s.
    """
    qd = np.asarray(qd)
    return (np.asarray(modes) == 1) & np.all(np.abs(qd) <= NEAR_REST_RATE_RAD_S + 1e-12,
                                             axis=-1)  # fmt: skip


def at_rest(modes, qd) -> np.ndarray:
    """Which states are starts at rest: model 1, every joint rate below AT_REST_RATE_RAD_S.

    ``modes`` (n,) and ``qd`` (n, 6), or one state's mode and (6,) rates (then a 0-d array).
    The env's first-step flag and the model-based teacher's start phase both use it.
    """
    qd = np.asarray(qd)
    return (np.asarray(modes) == 1) & np.all(np.abs(qd) < AT_REST_RATE_RAD_S, axis=-1)


PHASE_NAMES = ("first_step", "model_time_s")
"""The entries ``phase_obs`` appends to the observation."""
PHASE_LOW = np.array([0.0, 0.0])
PHASE_HIGH = np.array([1.0, MODEL_TIME_MAX_S])


class ContactClock:
    """First-step flags, models and periods since each model began, for N environments."""

    def __init__(self, n: int, dt: float):
        """Clocks for ``n`` environments with control period ``dt`` [s]."""
        self.dt = float(dt)
        self.first = np.zeros(n, bool)
        self.opening = np.zeros(n, bool)  # a start near rest's first contact phase
        self.mode = np.ones(n, np.int64)
        self.j = np.zeros(n, np.int64)

    def start(self, idx: np.ndarray, modes: np.ndarray, qd: np.ndarray) -> None:
        """Slots ``idx`` start in ``modes`` with joint rates ``qd`` (len(idx), 6)."""
        self.first[idx] = at_rest(modes, qd)
        self.opening[idx] = near_rest(modes, qd)
        self.mode[idx] = modes
        self.j[idx] = 0

    def advance(self, modes_after: np.ndarray, steps_after: np.ndarray, stepped=None) -> None:
        """Move the clocks past a period, given each environment's model and completed steps.

        ``stepped`` (bool mask, default all) marks the environments stepped in the period.
        """
        same = modes_after == self.mode
        j = np.where(same, self.j + 1, 0)
        first = self.first & (steps_after == 0)
        opening = self.opening & same
        if stepped is None:
            self.j, self.first, self.opening = j, first, opening
            self.mode = np.asarray(modes_after, np.int64).copy()
        else:
            self.j[stepped], self.first[stepped] = j[stepped], first[stepped]
            self.opening[stepped] = opening[stepped]
            self.mode[stepped] = modes_after[stepped]

    def model_time_s(self) -> np.ndarray:
        """(n,): the time since each environment's current model began [s] (unclipped)."""
        return self.j * self.dt

    def features(self) -> np.ndarray:
        """(n, 2): the first-step flag and the time in the current model [s] (clipped)."""
        t = np.minimum(self.j * self.dt, MODEL_TIME_MAX_S)
        return np.stack([self.first.astype(np.float64), t], axis=1)
