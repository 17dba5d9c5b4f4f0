"""The env's settings: every keyword argument validated once, in groups, into one frozen object.

Both envs build an :class:`EnvSettings` from ``gym.make`` / ``gym.make_vec`` keyword arguments
(:func:`make_settings`) and keep it as ``settings``: the physics (robot, fidelity options,
control period), the task (its name, the reference walk, the fall height), the start
distribution, the action mapping, the reward (:mod:`.rewards`' registry), the observation and
the perturbations (:mod:`.perturbations`). ``repr(settings)`` prints them and
:meth:`EnvSettings.as_dict` gives them as data (training runs save it).

One keyword argument per part, each a name or a dict of that part's settings:
``physics`` (the integrator options: :data:`PHYSICS_KEYS`, on top of ``preset``), ``action``
(:data:`~.actions.ACTION_KEYS`), ``start`` (a start's name, a dict of component weights, or
:data:`START_KEYS`), ``reward`` (a kind's name or ``{"kind", "weights", "kernels", ...}``),
``termination`` (:func:`~.terminations.termination_keys`), ``observation`` (a list of
:data:`OBSERVATION_BLOCKS`), ``perturbations`` and ``command``; besides them ``task``, ``preset``,
``dt``, ``params``, ``reference`` and ``render_mode``. A retired flat keyword is refused with
its new place (:data:`MOVED`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .actions import ActionSettings, action_settings
from .command import CommandSettings, command_settings
from .model import BipedParams, paper_biped
from .observation import OBSERVATION_BLOCKS
from .options import SimOptions
from .perturbations import PerturbationSettings, perturbation_settings
from .reference import OWN_REFERENCE, REFERENCES
from .rewards import RewardSettings, reward_settings
from .starts import (
    NOMINAL_POSTURE_RAD,
    RESET_NOISE_SCALE_RAD,
    check_start_kind,
    check_start_settings,
    split_reference,
    start_name,
)
from .tasks import TASKS, resolve_options, resolve_task
from .terminations import TerminationSettings, termination_keys, termination_settings
from .validation import (
    check_choice,
    check_mapping,
    check_names,
)

PHYSICS_KEYS = ("integrator", "substeps", "impact", "locate_events", "jdot", "strict",
                "heel_force_includes_foot_weight", "step_tol", "stop_at_switch")  # fmt: skip
"""Keys of the ``physics`` dict: :class:`~.options.SimOptions` overrides on top of the preset."""
START_KEYS = ("kind", "posture", "reset_noise_scale")
"""Keys of the ``start`` dict: the start (a name or component weights, the reference states'
among them), the rest posture (6,) [rad] and the reset noise [rad]."""


@dataclass(frozen=True)
class PhysicsSettings:
    """The robot, the fidelity preset with its per-option overrides, and the control period."""

    params: BipedParams
    preset: str
    options: SimOptions
    dt: float


@dataclass(frozen=True)
class StartSettings:
    """The start distribution, rest posture and reset noise.

    The distribution is a name, or a mixture ((component, weight), ...).
    """

    start: str | tuple[tuple[str, float], ...]
    posture: tuple[float, ...]
    reset_noise_scale: float

    @property
    def reference_fraction(self) -> float:
        """The fraction of starts at a reference state (the ``"reference"`` component)."""
        return split_reference(self.start)[0]


@dataclass(frozen=True)
class ObservationSettings:
    """Blocks appended to the 24 base entries (:data:`~.observation.OBSERVATION_BLOCKS`)."""

    blocks: tuple[str, ...] = ()

    @property
    def phase_obs(self) -> bool:
        """Whether the contact clock's phase is observed."""
        return "phase" in self.blocks

    @property
    def needs_clock(self) -> bool:
        """Whether a block reads the contact clock."""
        return any(OBSERVATION_BLOCKS[b].needs_clock for b in self.blocks)


@dataclass(frozen=True)
class EnvSettings:
    """Every setting of an env, validated (see the module docstring)."""

    task: str
    physics: PhysicsSettings
    start: StartSettings
    action: ActionSettings
    reward: RewardSettings
    observation: ObservationSettings
    perturbations: PerturbationSettings
    reference: str
    termination: TerminationSettings = TerminationSettings()
    command: CommandSettings | None = None
    """The commanded speed (:mod:`.command`; None: no command)."""

    @property
    def fall_hip_height_m(self) -> float | None:
        """A fall's hip height [m] (None: off)."""
        return self.termination.fall_hip_height_m

    @property
    def time_limit_s(self) -> float | None:
        """The episode's time limit [s] of simulated time (None: none)."""
        return self.termination.time_limit_s

    @property
    def dt(self) -> float:
        """The control period [s]."""
        return self.physics.dt

    @property
    def needs_reference(self) -> bool:
        """Whether an option reads the reference walk (reward, starts, observation, PD base)."""
        return (self.reward.kind == "tracking" or self.start.reference_fraction > 0
                or self.action.needs_reference)  # fmt: skip

    @property
    def needs_clock(self) -> bool:
        """Whether the env keeps a contact clock (phase observed, the gait reward, a reference)."""
        return (self.observation.needs_clock or self.reward.kind in ("gait", "command")
                or self.termination.needs_clock or self.needs_reference)  # fmt: skip

    def as_dict(self) -> dict[str, Any]:
        """The settings as plain data (numbers, strings, lists), in their groups."""

        def plain(x):
            if isinstance(x, tuple | list):
                return [plain(v) for v in x]
            if isinstance(x, np.ndarray):
                return x.tolist()
            return x

        out: dict[str, Any] = {"task": self.task, "reference": self.reference}
        p = self.physics
        out["physics"] = {
            "params": "paper_biped" if p.params == paper_biped() else "custom",
            "preset": p.preset,
            "dt": p.dt,
            "options": {k: plain(v) for k, v in dataclasses.asdict(p.options).items()},
        }
        for name in ("start", "action", "observation", "perturbations"):
            group = getattr(self, name)
            out[name] = {f.name: plain(getattr(group, f.name)) for f in dataclasses.fields(group)}
        out["termination"] = self.termination.as_dict()
        out["start"]["start"] = start_name(self.start.start)
        out["reward"] = self.reward.as_dict()
        out["command"] = None if self.command is None else {
            f.name: plain(getattr(self.command, f.name)) for f in dataclasses.fields(self.command)
        }  # fmt: skip
        return out


def _with_kind(spec: Any, task_reward: str | dict) -> Any:
    """The ``reward`` kwarg on top of the task's (a kind, or a dict of the reward's settings).

    None: the task's; a dict naming no kind, or the task's kind: merged onto the task's.
    """
    task = {"kind": task_reward} if isinstance(task_reward, str) else task_reward
    if spec is None:
        return task_reward
    if isinstance(spec, dict) and spec.get("kind", task["kind"]) == task["kind"]:
        return {**task, **spec}
    return spec


def _reference(reference: Any, start: str | tuple) -> str:
    """The reference walk: a shipped name, "own" (each start its kind's) or an npz path.

    None: the start's own ("rest", "midstride"; "own" for mixed starts).
    """
    if reference is None:
        if not isinstance(start, str):  # a mixture: "own" where it holds rest starts
            return OWN_REFERENCE if "rest" in dict(start) else "midstride"
        return {"rest": "rest", "mixed": OWN_REFERENCE}.get(start, "midstride")
    known = (*REFERENCES, OWN_REFERENCE)
    if not isinstance(reference, str) or not (
        reference in known or (reference.endswith(".npz") and Path(reference).is_file())
    ):
        raise ValueError(f"reference must be one of {known} or an npz path, got {reference!r}")
    return reference


RSI_MOVED = ("start={'kind': {'reference': 0.5, 'midstride': 0.5}} (the reference states "
             "are a start component; its weight is their fraction)")  # fmt: skip
"""Where the fraction of reference-state starts went (a refused ``rsi`` names it)."""


def start_dict(spec: Any) -> dict[str, Any]:
    """A ``start`` value as a dict of :data:`START_KEYS` (a name or weights: its ``kind``).

    None: an empty dict (the task's start).
    """
    if spec is None:
        return {}
    if isinstance(spec, dict) and "rsi" in spec:
        raise ValueError(f"start's 'rsi' moved: {RSI_MOVED}")
    if isinstance(spec, dict) and set(spec) & set(START_KEYS):
        return dict(check_mapping("start", spec, START_KEYS))
    return {"kind": spec}


def with_keys(kwargs: dict[str, Any], part: str, **keys: Any) -> dict[str, Any]:
    """The env's keyword arguments ``kwargs`` with ``keys`` set inside the dict of ``part``.

    For the dict parts (``physics``, ``start``, ``termination``, ``action``, ``perturbations``,
    ``command``):
    ``with_keys(kw, "termination", time_limit_s=None)`` keeps the part's other keys.
    """
    cur = kwargs.get(part)
    if part == "start":
        base = start_dict(cur)
    elif part == "action":
        base = {} if cur is None else ({"kind": cur} if isinstance(cur, str) else dict(cur))
    elif part in ("physics", "termination", "perturbations", "command"):
        base = {} if cur is None else dict(cur)
    else:
        raise ValueError(f"with_keys: {part!r} is not a dict part of the env")
    return {**kwargs, part: {**base, **keys}}


def _observation(blocks: Any, command: bool) -> ObservationSettings:
    """The ``observation`` kwarg: a list of :data:`~.observation.OBSERVATION_BLOCKS`.

    A name: one block; the command's block follows with the command option.
    """
    own = tuple(b for b in OBSERVATION_BLOCKS if b != "command")
    blocks = (blocks,) if isinstance(blocks, str) else blocks
    if not isinstance(blocks, list | tuple):
        raise ValueError(f"observation must be a list of blocks from {own}, got {blocks!r}")
    for b in blocks:
        check_choice("observation block", b, own)
    if len(set(blocks)) != len(blocks):
        raise ValueError(f"observation: a block appears twice in {list(blocks)}")
    return ObservationSettings(tuple(blocks) + (("command",) if command else ()))


def make_settings(
    task: str = "walk",
    preset: str | None = None,
    dt: float | None = None,
    params: BipedParams | None = None,
    physics: dict[str, Any] | None = None,
    action: str | dict | None = None,
    start: str | dict | None = None,
    reward: str | dict | None = None,
    termination: dict[str, Any] | None = None,
    observation: list[str] | tuple[str, ...] | None = None,
    perturbations: dict[str, Any] | None = None,
    command: dict[str, Any] | None = None,
    reference: str | None = None,
    **unknown: Any,
) -> EnvSettings:
    """Validate the env's keyword arguments (``ConstrainedBipedEnv``'s docstring) once.

    ``task`` (:data:`~.tasks.TASKS`) sets the defaults of the parts it names; each one given
    explicitly overrides the task's (``physics`` and ``start`` dicts key by key, ``action`` and
    ``reward`` dicts key by key onto the task's of the same kind).
    """
    for key in unknown:
        if key in MOVED:
            raise ValueError(f"{key} is now {MOVED[key]} (one keyword per part)")
        if key in RETIRED:
            raise ValueError(f"{key}: {RETIRED[key]}")
    check_names("argument(s) of ConstrainedBiped-v0", unknown, ENV_ARGUMENTS + ("render_mode",))
    params = paper_biped() if params is None else params
    t = resolve_task(task, preset=preset, dt=dt, reward=reward, action=action,
                     observation=observation, command=command)  # fmt: skip
    task_t = TASKS[task]
    given_physics = check_mapping("physics", {} if physics is None else physics, PHYSICS_KEYS)
    sim = {**task_t.get("physics", {}), **given_physics}
    options = resolve_options(t["preset"], t["dt"], sim)
    dt = float(t["dt"])
    st = {**start_dict(task_t["start"]), **start_dict(start)}
    start_kind, q0, noise = check_start_settings(
        params, st["kind"], st.get("posture", NOMINAL_POSTURE_RAD),
        st.get("reset_noise_scale", RESET_NOISE_SCALE_RAD))  # fmt: skip
    reward_s = reward_settings(_with_kind(reward, task_t.get("reward", "env")))
    commands = command_settings(t.get("command"))
    if (reward_s.kind == "command") != (commands is not None):
        raise ValueError("reward='command' and the command option go together: reward kind "
                         f"{reward_s.kind!r}, command {t.get('command')!r}")  # fmt: skip
    term = termination_settings(termination)
    if term.get("max_stop_s") is not None and commands is None:
        raise ValueError("termination max_stop_s needs a command (task='command')")
    return EnvSettings(
        task=task,
        physics=PhysicsSettings(params, t["preset"], options, dt),
        start=StartSettings(start_kind, tuple(q0.tolist()), noise),
        action=action_settings(action, task_t.get("action", "torque"), dt),
        reward=reward_s,
        observation=_observation(t["observation"], commands is not None),
        perturbations=perturbation_settings(perturbations),
        reference=_reference(reference, start_kind),
        termination=term,
        command=commands,
    )


def with_start_kind(settings: EnvSettings, start: str | dict) -> EnvSettings:
    """``settings`` whose starts are drawn from ``start`` (a start's name or mixture of weights).

    What an env's ``set_start`` validates: the rest posture and reset noise stay; a start that
    changes whether the env reads the reference walk (a ``"reference"`` component where it had
    none, or the reverse) is refused: the walk is loaded, or not, when the env is made.
    """
    kind = check_start_kind(start)
    had = settings.start.reference_fraction > 0
    if (split_reference(kind)[0] > 0) != had:
        raise ValueError(
            "set_start: the 'reference' start component is fixed when the env is made "
            f"({'with' if had else 'without'} it here), got {start_name(kind)!r}"
        )
    return dataclasses.replace(settings, start=dataclasses.replace(settings.start, start=kind))


RETIRED = {
    "restarts": "removed (starts at states the env visited itself never produced a walker; "
    "docs/ablations.md)",
    "reference_obs": "removed (no committed policy saw the reference in its input; "
    "docs/ablations.md)",
}
"""Arguments the env no longer takes, each refused with why (the package is unreleased)."""

MOVED = {
    **{k: f"physics={{{k!r}: ...}}" for k in PHYSICS_KEYS},
    **{k: f"action={{{k!r}: ...}}" for k in ("torque_limit_nm", "out_of_range")},
    **{k: f"start={{{k!r}: ...}}" for k in ("posture", "reset_noise_scale")},
    "rsi": RSI_MOVED,
    **{k: f"termination={{{k!r}: ...}}" for k in termination_keys()},
    "phase_obs": "observation=['phase']",
    **{k: f"reward={{'kind': 'env', 'weights': {{{t!r}: ...}}}}"
       for k, t in (("forward_reward_weight", "forward"), ("alive_bonus", "alive"),
                    ("switch_bonus", "switch"), ("step_bonus", "step"),
                    ("ctrl_cost_weight", "ctrl"))},
}  # fmt: skip
"""The flat keywords that became a part's key, each refused naming its new place."""

ENV_ARGUMENTS: tuple[str, ...] = tuple(
    name for name in make_settings.__code__.co_varnames[: make_settings.__code__.co_argcount]
)
"""The keyword arguments of ``gym.make("ConstrainedBiped-v0", ...)`` besides ``render_mode``
(a misspelt one raises a ValueError listing these)."""
