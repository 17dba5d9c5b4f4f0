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

from dataclasses import dataclass

import numpy as np

from .rewards import REWARD_KINDS, RewardSettings, RewardTerm

SWING_MODELS = (1, 2)
"""The models in which the swing leg is free (its foot off the ground)."""
_SWINGING = np.isin(np.arange(5), SWING_MODELS)  # indexed by the model, 1-4
_SWINGING.flags.writeable = False


@dataclass(frozen=True)
class Period:
    """A control period's inputs of the gait and command terms, one entry per row.

    ``speed``: the hip's mean forward speed [m/s] (progress / dt); ``hip_z`` [m]; ``swing_vy``:
    the swing ankle's forward speed [m/s]; ``modes``: the models after it; ``model_time_s``: the
    time since the current model began [s]; ``steps``: steps completed in it; ``command``: the
    commanded speeds [m/s] it ran under (None: the gait reward's constant target);
    ``tau_sq``: sum(tau^2) of the period's torques [N^2 m^2] (its time mean where they vary);
    ``first_phase``: the rows still in a start near rest's first contact phase (None: none);
    ``switches``: forward model switches in it (None: not recorded); ``contact_fn``: the point
    contact's normal force at its start under its torques [N], NaN where not computed (None:
    not computed at all); ``avg_speed``: the hip speed averaged over the command reward's
    ``speed_window_s`` [m/s] (None: off).
    """

    speed: np.ndarray
    hip_z: np.ndarray
    swing_vy: np.ndarray
    modes: np.ndarray
    model_time_s: np.ndarray
    steps: np.ndarray
    command: np.ndarray | None = None
    tau_sq: np.ndarray | None = None
    first_phase: np.ndarray | None = None
    switches: np.ndarray | None = None
    contact_fn: np.ndarray | None = None
    avg_speed: np.ndarray | None = None


def kernel(reward, name: str, error) -> np.ndarray:
    """exp(-kernel * error^2) with the term ``name``'s kernel."""
    return np.exp(-reward.kernels[name] * error**2)


def reference_speed(r, p: Period, term: str):
    """The speed a term measures against [m/s]: each row's command, else the term's target."""
    return r.targets[term] if p.command is None else p.command


def speed_term(r, p: Period) -> np.ndarray:
    """The period's mean hip speed against the command or target (zero: standing still)."""
    return kernel(r, "speed", p.speed - reference_speed(r, p, "speed"))


def height_term(r, p: Period) -> np.ndarray:
    """The hip height against its target (no crouch, no vault)."""
    return kernel(r, "height", p.hip_z - r.targets["height"])


def swing_term(r, p: Period) -> np.ndarray:
    """Models 1, 2: the swing ankle moving forward at the command or target; models 3, 4: 1."""
    short = np.minimum(p.swing_vy - reference_speed(r, p, "swing"), 0.0)
    return np.where(_SWINGING[p.modes], kernel(r, "swing", short), 1.0)


def cadence_targets(r, p: Period, stretch=1.0) -> np.ndarray:
    """Each row's cadence target [s].

    Its model's (times ``stretch``), or in a start near rest's first contact phase the
    reward's ``first_phase_s`` where it is set.
    """
    target = r.cadence[p.modes] * stretch
    if r.first_phase_s is None or p.first_phase is None:
        return target
    return np.where(p.first_phase, r.first_phase_s, target)


def cadence_term(r, p: Period) -> np.ndarray:
    """The time held in the current model against its target (the contact clock)."""
    return kernel(r, "cadence", np.maximum(p.model_time_s - cadence_targets(r, p), 0.0))


def steps_term(r, p: Period) -> np.ndarray:
    """The steps completed in the period."""
    return p.steps


def switches_term(r, p: Period) -> np.ndarray:
    """The forward model switches in the period (four per step; zeros where not recorded)."""
    return np.zeros_like(p.steps) if p.switches is None else p.switches


REWARD_KINDS["gait"] = (
    RewardTerm("speed", 0.4, 0.5, target=1.1, value=speed_term, gated=True,
               doc="kernel of (the period's mean hip speed - target [m/s])^2"),
    RewardTerm("height", 0.2, 50.0, target=2.95, value=height_term, gated=True,
               doc="kernel of (hip height - target [m])^2"),
    RewardTerm("swing", 0.2, 1.0, target=1.0, value=swing_term, gated=True,
               doc="models 1, 2: kernel of min(0, swing ankle speed - target [m/s])^2; "
                   "models 3, 4: the weight"),
    RewardTerm("cadence", 0.2, 10.0, target=0.7, per_model=True, value=cadence_term, gate=True,
               doc="kernel of max(0, time in the current model - target [s])^2; the target one "
                   "value or one per model (1-4)"),
    RewardTerm("step", 1.0, value=steps_term, per_period=False,
               doc="weight per completed walking step"),
    RewardTerm("switch", 0.0, value=switches_term, per_period=False,
               doc="weight per forward model switch (four per step; off by default)"),
)  # fmt: skip
GAIT_TERMS = tuple(t.name for t in REWARD_KINDS["gait"])
"""The gait reward's terms, in order (a new one is one entry above: its spec and function)."""


class GaitReward:
    """The gait reward of N rows: its weights, kernels and targets, and its terms per period.

    The command reward (:class:`~.command.CommandReward`) is the same machinery over its own
    named terms (:attr:`KIND`).
    """

    KIND = "gait"

    def __init__(self, reward: RewardSettings, dt: float, n: int):
        """For ``reward`` (kind :attr:`KIND`), control period ``dt`` [s] and ``n`` rows."""
        if reward.kind != self.KIND:
            raise ValueError(f"{type(self).__name__} takes the {self.KIND!r} reward, "
                             f"not {reward.kind!r}")  # fmt: skip
        self.specs = REWARD_KINDS[self.KIND]
        names = reward.terms
        self.dt = float(dt)
        self.weights = {t: reward.weight(t) for t in names}
        self.kernels = {t: reward.kernel(t) for t in names}
        self.targets = {t: reward.target(t) for t in names
                        if t != "cadence" and reward.target(t) is not None}  # fmt: skip
        self.cadence = np.zeros(5)  # indexed by the model, 1-4
        self.cadence[1:] = reward.target("cadence")
        self._gated = reward.gated
        self.first_phase_s = reward.first_phase_s
        self._live = [c for c, t in enumerate(self.specs) if t.per_period]

    def terms(self, progress_m, hip_z, swing_vy, modes, model_time_s, steps, alive, command=None,
              tau_sq=None, first_phase=None, switches=None, contact_fn=None,
              avg_speed=None):  # fmt: skip
        """(n, k + 1): the terms (the kind's order) and their sum, after a period.

        ``progress_m``: the hip's forward progress in the period [m]; ``alive``: periods not
        ended by an event (the others earn only the terms not ``per_period``: the steps); the
        rest as :class:`Period`'s.
        """
        p = Period(progress_m / self.dt, hip_z, swing_vy, modes, model_time_s, steps, command,
                   tau_sq, first_phase, switches, contact_fn, avg_speed)  # fmt: skip
        out = np.empty((len(progress_m), len(self.specs) + 1))
        gate = None
        for c, t in enumerate(self.specs):
            value = t.value(self, p)
            out[:, c] = self.weights[t.name] * value
            if t.gate:
                gate = value
        if self._gated and gate is not None:
            for c, t in enumerate(self.specs):
                if t.gated:
                    out[:, c] *= gate
        if not alive.all():
            out[np.ix_(~alive, self._live)] = 0.0
        out[:, -1] = out[:, :-1].sum(axis=1)
        return out
