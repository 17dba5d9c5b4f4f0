"""The reward registry, the compiled walking reward and the terminations beyond the events.

Every reward *kind* is a tuple of named terms with their weights and, for kernel terms, their
kernel scales, as data (:data:`REWARD_KINDS`); an env's ``reward`` kwarg picks a kind and may
override any weight or kernel (``reward={"kind": "tracking", "weights": {"pose": 0.6}}``), and
the chosen values are part of the env's settings (``env.unwrapped.settings.reward``), saved with
every training run. ``info["reward_<term>"]`` gives each term of the env's kind; they add up to
the reward. Shared by both envs.

* ``"env"`` (the walking task's own): hip progress, an alive bonus, a bonus per forward model
  switch and per completed step, and a torque cost (:func:`nb_reward_terms`, in the compiled
  period).
* ``"tracking"`` (a reference walk's, :mod:`.tracking`): DeepMimic-style exponential kernels of
  the pose, rate, hip-height and hip-speed errors against the reference at the contact clock,
  plus a bonus per completed step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .jit import njit_noalloc
from .modes import N_MODELS
from .state import ST_MODE
from .validation import check_choice, check_mapping, check_real

TERMINATION_NON_FINITE = "non_finite"
"""The reason of an episode whose numerical state blew up."""
TERMINATION_FALL = "fall"
"""The reason of an episode ended by ``fall_hip_height_m`` (the hip below it)."""


@dataclass(frozen=True)
class RewardTerm:
    """One named reward term: its default weight and, for a kernel term, its kernel scale.

    A kernel term is weight * exp(-kernel * squared error); ``target``, where the term has one,
    is the value its error is measured from (the gait reward's commanded speed, height...).
    """

    name: str
    weight: float
    kernel: float | None = None
    doc: str = ""
    target: float | None = None
    per_model: bool = False
    """The target may be one value per model (1-4) instead of one for all."""
    value: Callable | None = None
    """``value(reward, period) -> (n,)``: the term before its weight, for the kinds computed
    in Python from the per-period record (gait, command); None where the compiled period
    (env) or the reference (tracking) computes it."""
    gated: bool = False
    """Multiplied by the gate term's value when the reward is ``gated``."""
    gate: bool = False
    """The term whose value gates the others (the contact clock's kernel)."""
    per_period: bool = True
    """Zero for a period ended by an event (False: the steps, earned however it ended)."""


REWARD_KINDS: dict[str, tuple[RewardTerm, ...]] = {
    "env": (
        RewardTerm("forward", 1.0, doc="weight * hip progress / dt [m/s]"),
        RewardTerm("alive", 0.5, doc="weight per period not ended by an event"),
        RewardTerm("switch", 1.0, doc="weight per forward model switch"),
        RewardTerm("step", 5.0, doc="weight per completed walking step"),
        RewardTerm("ctrl", 0.1, doc="-weight * sum((tau / limit)^2)"),
    ),
    "tracking": (
        RewardTerm("pose", 0.5, 5.0, "kernel of the six angles' squared error [rad^2]"),
        RewardTerm("velocity", 0.1, 0.05, "kernel of their rates' squared error [(rad/s)^2]"),
        RewardTerm("hip_height", 0.2, 200.0, "kernel of the hip height's squared error [m^2]"),
        RewardTerm("hip_speed", 0.2, 5.0, "kernel of the hip speed's squared error [(m/s)^2]"),
        RewardTerm("step", 1.0, doc="weight per completed walking step"),
    ),
}
"""The reward kinds and their terms: "env" and "tracking" here; "gait" and "command" register
their named term functions with them (:mod:`.gait`, :mod:`.command`), one entry per term. The
tracking kernels' weights sum to 1 (a period on the
reference earns 1) and each halves its term at an error of about 0.37 rad (one angle),
3.7 rad/s, 59 mm and 0.37 m/s; a step takes about 170 periods of 5 ms. The gait kernels' weights
sum to 1 too, with no recorded motion: its targets are round numbers of the task (a 1.1 m/s walk
at the hip height of a straight-legged stance, the swing foot moving forward, no contact phase
held beyond 0.7 s), overridable (``reward={"kind": "gait", "targets": {"speed": 0.8}}``).
``reward={"kind": "gait", "gated": True}`` multiplies the speed, height and swing terms by the
cadence kernel (in [0, 1]): a contact phase held past its target earns nothing, as a periodic
clock gates the task terms of Siekmann et al. (2021)."""

REWARD_TERMS = tuple(f"reward_{t.name}" for t in REWARD_KINDS["env"])
"""``info`` keys of the walking reward's terms (the compiled reward's columns, in order)."""


@dataclass(frozen=True)
class RewardSettings:
    """The validated reward of an env: its kind and each term's weight and kernel."""

    kind: str
    weights: tuple[float, ...]
    kernels: tuple[float | None, ...]
    targets: tuple[float | tuple[float, ...] | None, ...] = ()
    gated: bool = False
    """The gait reward: its task terms multiplied by the cadence kernel."""
    first_phase_s: float | None = None
    """The gait and command rewards: the cadence target of a start near rest's first contact phase
    [s] (None: its model's target)."""
    speed_window_s: float | None = None
    """The command reward: its ``speed`` term measures the hip speed averaged over this time
    constant [s] (an exponential average of the periods' mean speeds, begun at each start)
    while a speed is commanded, so a slow walk may pause in double support between steps
    (None: each period's own mean speed)."""

    @property
    def terms(self) -> tuple[str, ...]:
        """The kind's term names, in order."""
        return tuple(t.name for t in REWARD_KINDS[self.kind])

    @property
    def info_keys(self) -> tuple[str, ...]:
        """The ``info`` keys of the terms (``reward_<term>``)."""
        return tuple(f"reward_{t}" for t in self.terms)

    def weight(self, term: str) -> float:
        """The weight of ``term``."""
        return self.weights[self.terms.index(term)]

    def kernel(self, term: str) -> float:
        """The kernel scale of ``term`` (a kernel term)."""
        return self.kernels[self.terms.index(term)]

    def target(self, term: str) -> float | tuple[float, ...]:
        """The target of ``term`` (a term with one; one per model where it was given so)."""
        return self.targets[self.terms.index(term)]

    def as_dict(self) -> dict[str, Any]:
        """``{"kind", "weights", "kernels"[, "targets", "gated"]}`` as ``reward`` takes it."""
        kernels = {t: k for t, k in zip(self.terms, self.kernels, strict=True) if k is not None}
        out = {"kind": self.kind, "weights": dict(zip(self.terms, self.weights, strict=True)),
               "kernels": kernels}  # fmt: skip
        targets = {t: (list(v) if isinstance(v, tuple) else v)
                   for t, v in zip(self.terms, self.targets, strict=True)
                   if v is not None}  # fmt: skip
        if targets:
            out["targets"] = targets
        if self.gated:
            out["gated"] = True
        if self.first_phase_s is not None:
            out["first_phase_s"] = self.first_phase_s
        if self.speed_window_s is not None:
            out["speed_window_s"] = self.speed_window_s
        return out


def reward_settings(reward: Any) -> RewardSettings:
    """The ``reward`` kwarg: a kind's name or ``{"kind", "weights", "kernels", ...}``.

    The dict's other keys: ``"targets"`` (the gait reward's), ``"gated"`` (the gait
    reward's task terms gated by the cadence kernel), ``"first_phase_s"`` (the gait and
    command rewards: the cadence target of a start near rest's first contact phase [s]) and
    ``"speed_window_s"`` (the command reward: the ``speed`` term's averaging time [s]).
    """
    spec = {"kind": reward} if isinstance(reward, str) else reward
    check_mapping("reward", spec, ("kind", "weights", "kernels", "targets", "gated",
                                   "first_phase_s", "speed_window_s"))  # fmt: skip
    kind = check_choice("reward kind", spec.get("kind", "env"), sorted(REWARD_KINDS))
    terms = REWARD_KINDS[kind]
    names = [t.name for t in terms]
    weights = {t.name: t.weight for t in terms}
    kernels = {t.name: t.kernel for t in terms}
    for name, value in check_mapping("reward weights", spec.get("weights", {}), names).items():
        weights[name] = check_real(f"reward weight {name!r}", value, 0.0, REWARD_WEIGHT_MAX)
    kernel_names = [t.name for t in terms if t.kernel is not None]
    for name, value in check_mapping("reward kernels", spec.get("kernels", {}),
                                     kernel_names).items():  # fmt: skip
        kernels[name] = check_real(f"reward kernel {name!r}", value, 0.0, REWARD_WEIGHT_MAX,
                                   low_open=True)  # fmt: skip
    targets = {t.name: t.target for t in terms}
    target_names = [t.name for t in terms if t.target is not None]
    per_model = {t.name for t in terms if t.per_model}
    for name, value in check_mapping("reward targets", spec.get("targets", {}),
                                     target_names).items():  # fmt: skip
        targets[name] = _target(name, value, name in per_model)
    gated = spec.get("gated", False)
    if gated is not False and kind not in ("gait", "command"):
        raise ValueError(f"reward 'gated' is a setting of the 'gait' and 'command' rewards, "
                         f"not {kind!r}'s")  # fmt: skip
    if not isinstance(gated, bool):
        raise ValueError(f"reward 'gated' must be a bool, got {gated!r}")
    first = spec.get("first_phase_s")
    if first is not None:
        if kind not in ("gait", "command"):
            raise ValueError(f"reward 'first_phase_s' is a setting of the 'gait' and 'command' "
                             f"rewards, not {kind!r}'s")  # fmt: skip
        first = check_real("reward 'first_phase_s'", first, 0.0, 1e3, unit=" [s]")
    window = spec.get("speed_window_s")
    if window is not None:
        if kind != "command":
            raise ValueError(f"reward 'speed_window_s' is a setting of the 'command' reward, "
                             f"not {kind!r}'s")  # fmt: skip
        window = check_real("reward 'speed_window_s'", window, 0.0, 1e3, low_open=True,
                            unit=" [s]")  # fmt: skip
    return RewardSettings(kind, tuple(weights[n] for n in names),
                          tuple(kernels[n] for n in names),
                          tuple(targets[n] for n in names), gated, first, window)  # fmt: skip


def _target(name: str, value: Any, per_model: bool) -> float | tuple[float, ...]:
    """A checked target: a number, or for a per-model term one number per model (1-4)."""
    if per_model and isinstance(value, list | tuple):
        if len(value) != N_MODELS:
            raise ValueError(f"reward target {name!r} takes one number or {N_MODELS} "
                             f"(one per model), got {len(value)}")  # fmt: skip
        return tuple(check_real(f"reward target {name!r}", v, -REWARD_WEIGHT_MAX,
                                REWARD_WEIGHT_MAX) for v in value)  # fmt: skip
    return check_real(f"reward target {name!r}", value, -REWARD_WEIGHT_MAX, REWARD_WEIGHT_MAX)


REWARD_WEIGHT_MAX = 1e6
"""Largest accepted reward weight."""

CFG_FORWARD, CFG_ALIVE, CFG_SWITCH, CFG_STEP, CFG_CTRL, CFG_LIMIT, CFG_FALL, CFG_ENV = range(8)
N_ENV_TERMS = 6
"""Columns 0-5 of the per-period record: the "env" reward's five terms and their sum."""
REC_PROGRESS, REC_SWITCHES, REC_STEPS, REC_ALIVE, REC_TAU_SQ, REC_SWING_VY = range(6, 12)
N_RECORD = 12
"""The per-period record the compiled period writes for every row and every reward kind
(:func:`~.period.nb_env_period`): the "env" reward's terms and sum (columns 0-5, written for
that kind only), then the period's hip progress [m], forward model switches, completed steps,
whether no event or fall ended it (1/0), the time mean of sum(tau^2) [N^2 m^2] and the swing
ankle's forward speed after it [m/s]. Every reward kind's terms read it; zeros for rows not
stepped."""
"""Entries of :func:`reward_config`'s array."""


def reward_config(
    weights: tuple[float, ...],
    torque_limit_nm: float,
    fall_hip_height_m: float | None,
    env_kind: bool = True,
) -> np.ndarray:
    """The reward settings as one array, for :func:`nb_reward_terms`.

    The weights (REWARD_TERMS order), the torque bound [N m], the fall height [m] (-inf:
    off) and whether the env's reward is the "env" kind (its terms computed in the period),
    indexed by the CFG_* constants.
    """
    fall = -np.inf if fall_hip_height_m is None else fall_hip_height_m
    return np.array([*weights, torque_limit_nm, fall, float(env_kind)], dtype=np.float64)


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


def check_fall_height(fall_hip_height_m) -> float | None:
    """The validated fall height [m] (None: off)."""
    if fall_hip_height_m is None:
        return None
    return check_real("fall_hip_height_m", fall_hip_height_m, -10.0, 10.0, unit=" [m]")


# ----------------------------------------------------------------------------- reward parts
class EnvRewardPart:
    """The env's own reward: the compiled period's terms (:func:`nb_reward_terms`).

    Every part's :meth:`after` gives (terms (n, k), rewards (n,)) that the next period may
    overwrite (here: views of the record); the vector env copies its rewards.
    """

    def __init__(self):
        """Views of the record are made at the first period (the core's buffers)."""
        self._views = None

    def before(self, core):
        """Nothing to remember before the period."""
        return None

    def after(self, core, snap, terminated, skip):
        """(terms (n, k), rewards (n,)) of the period, as the compiled call wrote them."""
        if self._views is None:
            rew = core.buf.rew
            self._views = rew[:, : len(REWARD_TERMS)], rew[:, N_ENV_TERMS - 1]
        return self._views


class TrackingRewardPart:
    """``reward="tracking"``: kernels against the reference at the clock (``core.tracking``)."""

    def before(self, core):
        """Nothing to remember: the period's record holds its steps."""
        return None

    def after(self, core, snap, terminated, skip):
        """(terms, rewards) of the period; rows in ``skip`` earn nothing."""
        sim = core.sim
        track = core.tracking.reward(sim.q, sim.qd, core.hip, core.buf.rew[:, REC_STEPS],
                                     ~terminated)  # fmt: skip
        if skip is not None:
            track[skip] = 0.0
        return track[:, :-1], track[:, -1]


class GaitRewardPart:
    """``reward="gait"``: the task's and the contact clock's terms (``core.gait``)."""

    def before(self, core):
        """Nothing to remember: the period's record holds its progress and steps."""
        return None

    def after(self, core, snap, terminated, skip):
        """(terms, rewards) of the period; rows in ``skip`` earn nothing."""
        rec, sim = core.buf.rew, core.sim
        out = core.gait.terms(rec[:, REC_PROGRESS], core.hip[:, 1], rec[:, REC_SWING_VY],
                              sim.ist[:, ST_MODE], core.clock.model_time_s(),
                              rec[:, REC_STEPS], ~terminated,
                              tau_sq=rec[:, REC_TAU_SQ],
                              first_phase=core.clock.opening,
                              switches=rec[:, REC_SWITCHES])  # fmt: skip
        if skip is not None:
            out[skip] = 0.0
        return out[:, :-1], out[:, -1]


class CommandRewardPart:
    """``reward="command"``: the gait terms against each row's command (``core.commands``)."""

    def before(self, core):
        """The commands the period runs under, and the load term's forces (None: off).

        :meth:`~.command.CommandReward.start_toe_force`: the old stance toe's normal force at
        each row's start in model 4.
        """
        reward = core.command_reward
        load = reward.weights["load"] != 0.0
        return core.commands.v.copy(), (reward.start_toe_force(core) if load else None)

    def after(self, core, snap, terminated, skip):
        """(terms, rewards) of the period against the command it ran under."""
        command, contact_fn = snap
        rec, sim = core.buf.rew, core.sim
        reward = core.command_reward
        avg = reward.average_speed(rec[:, REC_PROGRESS], skip)
        out = reward.terms(rec[:, REC_PROGRESS], core.hip[:, 1], rec[:, REC_SWING_VY],
                           sim.ist[:, ST_MODE], core.clock.model_time_s(), rec[:, REC_STEPS],
                           ~terminated, command, tau_sq=rec[:, REC_TAU_SQ],
                           first_phase=core.clock.opening, switches=rec[:, REC_SWITCHES],
                           contact_fn=contact_fn, avg_speed=avg)  # fmt: skip
        if skip is not None:
            out[skip] = 0.0
        return out[:, :-1], out[:, -1]


REWARD_PARTS = {"env": EnvRewardPart, "tracking": TrackingRewardPart, "gait": GaitRewardPart,
                "command": CommandRewardPart}  # fmt: skip
"""The part that computes each reward kind's terms after a period, by kind."""
