"""The gait reward (``reward="gait"``): a walk's task and the contact clock, no recorded motion.

Every term is computed from the state after a control period, the period's hip progress, the
contact clock (the model and the time since it began) and the steps completed, against targets
of the task (:data:`~.rewards.REWARD_KINDS` ``"gait"``):

* ``speed``: weight * exp(-kernel * (hip progress / dt - target)^2), the commanded speed;
* ``height``: weight * exp(-kernel * (hip height - target)^2), posture (no crouch, no vault);
* ``swing`` (periodic foot speed): while the swing leg is free (models 1 and 2),
  weight * exp(-kernel * min(0, swing ankle's forward speed - target)^2), the swing foot
  carried forward; while the swing foot is down (models 3 and 4), the weight;
* ``cadence`` (periodic, the contact clock): weight * exp(-kernel * max(0, time in the current
  model - target)^2), no contact phase held longer than the target (one target for all models,
  or one per model: ``targets={"cadence": [0.6, 0.25, 0.15, 0.1]}``);
* ``step``: weight per completed walking step.

With ``gated`` the speed, height and swing terms are multiplied by the cadence kernel
(exp(-kernel * max(0, ...)^2), in [0, 1]): a contact phase held past its target earns nothing,
as Siekmann et al. (2021) gate their task terms by a periodic clock.

As with the tracking reward, every term is positive, so ending early never pays, and a period
ended by an event earns only its steps. The single and the batched env compute it here, once.
"""

from __future__ import annotations

import numpy as np

from .rewards import REWARD_KINDS, RewardSettings

SWING_MODELS = (1, 2)
"""The models in which the swing leg is free (its foot off the ground)."""
GAIT_TERMS = tuple(t.name for t in REWARD_KINDS["gait"])
"""The gait reward's terms, in order."""


class GaitReward:
    """The gait reward of N rows: its weights, kernels and targets, and its terms per period.

    The command reward (:class:`~.command.CommandReward`) shares this state and differs in
    :meth:`terms` only.
    """

    KIND = "gait"

    def __init__(self, reward: RewardSettings, dt: float, n: int):
        """For ``reward`` (kind :attr:`KIND`), control period ``dt`` [s] and ``n`` rows."""
        if reward.kind != self.KIND:
            raise ValueError(f"{type(self).__name__} takes the {self.KIND!r} reward, "
                             f"not {reward.kind!r}")  # fmt: skip
        names = reward.terms
        self.dt = float(dt)
        self._w = {t: reward.weight(t) for t in names}
        self._k = {t: reward.kernel(t) for t in names if t != "step"}
        self._target = {t: reward.target(t) for t in names
                        if t != "cadence" and reward.target(t) is not None}  # fmt: skip
        self._cadence = np.zeros(5)  # indexed by the model, 1-4
        self._cadence[1:] = reward.target("cadence")
        self._gated = reward.gated

    def terms(self, progress_m, hip_z, swing_vy, modes, model_time_s, steps, alive):
        """(n, 6): the terms (GAIT_TERMS order) and their sum, after a period.

        ``progress_m``: the hip's forward progress in the period [m]; ``hip_z`` [m];
        ``swing_vy``: the swing ankle's forward speed [m/s]; ``modes``: the models after it;
        ``model_time_s``: the time since the current model began [s]; ``steps``: steps completed
        in the period; ``alive``: periods not ended by an event (the others earn only steps).
        """
        w, k, tg = self._w, self._k, self._target
        out = np.empty((len(progress_m), len(GAIT_TERMS) + 1))
        out[:, 0] = w["speed"] * np.exp(-k["speed"] * (progress_m / self.dt - tg["speed"]) ** 2)
        out[:, 1] = w["height"] * np.exp(-k["height"] * (hip_z - tg["height"]) ** 2)
        short = np.minimum(swing_vy - tg["swing"], 0.0)
        free = np.isin(modes, SWING_MODELS)
        out[:, 2] = np.where(free, w["swing"] * np.exp(-k["swing"] * short**2), w["swing"])
        over = np.maximum(model_time_s - self._cadence[modes], 0.0)
        on_time = np.exp(-k["cadence"] * over**2)
        out[:, 3] = w["cadence"] * on_time
        if self._gated:
            out[:, :3] *= on_time[:, None]
        out[~alive, :4] = 0.0
        out[:, 4] = w["step"] * steps
        out[:, 5] = out[:, :5].sum(axis=1)
        return out
