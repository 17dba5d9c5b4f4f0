"""The command task: a commanded forward speed, observed, resampled, and the reward that follows it.

``command={"range": (lo, hi), "zero_fraction": p, "resample_s": (lo, hi), "deadband": d,
"ramp_m_s2": a}`` (``task="command"`` sets it: 0-2 m/s, 10% zero, a new command every 1-5 s, no
deadband, no ramp): each
row holds a commanded forward speed [m/s], drawn at its start (zero with probability
``zero_fraction``, else uniform in ``range``) and again every U(``resample_s``) seconds of
simulated time (``resample_s=None``: one command per episode), from the row's own generator,
after the start's and the perturbations' draws. The observation appends it (one entry,
``command_m_s``). A user sets it as a joystick would: ``env.unwrapped.set_command(v)`` (the
batched env: one value per row), or ``reset(options={"command": v})`` (the batched env: one, or
one per row); a command set so holds
until the next reset (no resampling). ``deadband`` [m/s] (0: off) is a joystick's dead zone:
every command, drawn or set, of size below it is held as exactly 0 (stop and stand), so the
observation, the reward and ``info["command_m_s"]`` see the 0 (legged_gym zeroes its drawn
commands below 0.2 m/s the same way). ``ramp_m_s2`` [m/s^2] (None: off) is a joystick's rate
limit: the held command moves toward a newly drawn or set one at this rate, a step before each
control period by the rate times the time since the last (a new episode starts at its command);
a stop from 2 m/s at 1.5 m/s^2 reaches 0 in 1.33 s (with a deadband of 0.2 m/s: 1.2 s), which
counts within the stop's time.

The reward (``reward="command"``) has no recorded motion: the terms of the gait reward
(:mod:`.gait`) with the command in place of its constant speed target, and a contact clock that
stops at a zero command:

* ``speed``: weight * exp(-kernel * (hip progress / dt - command)^2) (kernel 4: the field's
  exp(-e^2 / 0.25)); at a zero command it pays for standing still in model 4 (both feet down:
  weight * exp(-kernel * speed^2)) and half the weight in models 1-3, so that a walk stops by
  finishing its step into double support (:func:`command_speed_term`);
* ``height``: weight * exp(-kernel * (hip height - target)^2);
* ``swing``: models 1, 2: weight * exp(-kernel * min(0, swing ankle speed - command)^2), the
  swing foot carried forward at least at the command; models 3, 4: the weight;
* ``cadence``: weight * exp(-kernel * max(0, time in the model - target * stretch)^2), the
  targets (per model) stretched at slow commands by ``min(3, speed target / command)``; at a
  zero command the full weight (any contact state may be held: standing);
* ``step``: weight * min(1, command / speed target) per completed step (none at zero);
* ``effort``: weight * exp(-kernel * sum((tau / 150 N m)^2)), the torques' size (an energy
  term; weight 0 by default: off);
* ``still``: at a zero command, weight * exp(-kernel * speed^2) in every model: slowing paid
  on the way to a stop, not only once in model 4 (weight 0 by default: off);
* ``hold``: at a zero command, weight * exp(-kernel * speed^2) for a period spent wholly in
  model 4 (double support), a broad kernel: braking in double support pays from its first
  period, where the speed term still pays less than walking on (weight 0 by default: off);
* ``load``: at a zero command, for a period that starts in model 4, weight * exp(-kernel *
  (min(0, f_n - target) / 100 N)^2) of the old stance toe's normal force f_n at the period's
  start under its torques (torque actions; target 0 N by default): a walker that lifts that
  toe at once (f_n < 0, the switch to model 1) is paid more the less it pulls, a gradient
  toward staying in double support where the switch itself gives none (weight 0 by
  default: off).

``gated`` multiplies the speed, height and swing terms by the cadence kernel, as the gait reward.
Every term is positive; a period ended by an event earns only its steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .actions import TORQUE_LIMIT_NM
from .gait import GaitReward, cadence_targets, height_term, kernel, speed_term, swing_term
from .hybrid import FC_CONTACT, nb_evaluate
from .model import N_LINKS
from .rewards import REWARD_KINDS, RewardTerm
from .state import ST_MODE, ST_SIDE
from .validation import check_mapping, check_real

MAX_COMMAND_M_S = 5.0
"""Largest commanded speed accepted [m/s] (either way)."""
COMMAND_KEYS = ("range", "zero_fraction", "resample_s", "deadband", "ramp_m_s2")
"""Keys of the ``command`` dict."""
COMMAND_OBS_LOW = np.array([-MAX_COMMAND_M_S])
COMMAND_OBS_HIGH = np.array([MAX_COMMAND_M_S])
MAX_STRETCH = 3.0
"""The most a slow command stretches the cadence targets (a command of a third of the speed
target and below)."""


@dataclass(frozen=True)
class CommandSettings:
    """The validated ``command`` option (see the module docstring); None in the env: off."""

    range: tuple[float, float] = (0.0, 2.0)
    zero_fraction: float = 0.1
    resample_s: tuple[float, float] | None = (1.0, 5.0)
    deadband: float = 0.0
    ramp_m_s2: float | None = None


def _pair(name: str, value: Any, lo: float, hi: float, unit: str) -> tuple[float, float]:
    if isinstance(value, int | float) and not isinstance(value, bool):
        value = (value, value)
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ValueError(f"command {name} must be a number or (low, high), got {value!r}")
    a = check_real(f"command {name}", value[0], lo, hi, unit=unit)
    b = check_real(f"command {name}", value[1], lo, hi, unit=unit)
    if a > b:
        raise ValueError(f"command {name} must be (low, high) with low <= high, got {value!r}")
    return a, b


def command_settings(spec: Any) -> CommandSettings | None:
    """The ``command`` kwarg (None, or a dict of :data:`COMMAND_KEYS`) validated."""
    if spec is None:
        return None
    check_mapping("command", spec, COMMAND_KEYS)
    d = CommandSettings()
    resample = spec.get("resample_s", d.resample_s)
    ramp = spec.get("ramp_m_s2", d.ramp_m_s2)
    return CommandSettings(
        range=_pair("range", spec.get("range", d.range), -MAX_COMMAND_M_S, MAX_COMMAND_M_S,
                    " [m/s]"),  # fmt: skip
        zero_fraction=check_real("command zero_fraction", spec.get("zero_fraction",
                                                                   d.zero_fraction), 0.0, 1.0),
        resample_s=None if resample is None else _pair("resample_s", resample, 0.02, 1e4, " [s]"),
        deadband=check_real("command deadband", spec.get("deadband", d.deadband), 0.0,
                            MAX_COMMAND_M_S, unit=" [m/s]"),
        ramp_m_s2=None if ramp is None else check_real("command ramp_m_s2", ramp, 0.01, 1e3,
                                                       unit=" [m/s^2]"),
    )  # fmt: skip


def check_command(value: Any) -> float:
    """A commanded speed [m/s] given by a user (``set_command``, ``reset`` options)."""
    return check_real("command", value, -MAX_COMMAND_M_S, MAX_COMMAND_M_S, unit=" [m/s]")


def split_reset_options(
    options: Any, n: int | None = None
) -> tuple[Any, float | np.ndarray | None]:
    """``reset(options=...)`` as (the start's options or None, the command or None).

    ``{"command": v}`` alone draws the start as usual and holds the command ``v``. ``n``: the
    batched env's rows, where ``v`` may also be one command per row (returned as an (n,) array).
    """
    if not isinstance(options, dict) or "command" not in options:
        return options, None
    rest = {k: v for k, v in options.items() if k != "command"}
    return (rest or None), check_commands(options["command"], n, "reset option 'command'")


def check_commands(value: Any, n: int | None = None, what: str = "command"):
    """Commanded speeds given by a user, each checked by :func:`check_command`.

    One real number (a float), or with ``n`` (a batch's rows) one per row (an (n,) array).

    ``set_command`` and ``reset(options={"command": ...})`` both take them so: a string, a
    boolean, a list for one env or a value beyond :data:`MAX_COMMAND_M_S` is refused.
    """
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()  # numpy's 0-d array: one value
    if n is None or not isinstance(value, list | tuple | np.ndarray):
        return check_command(value)
    shape = value.shape if isinstance(value, np.ndarray) else (len(value),)
    if shape != (n,):
        raise ValueError(f"{what} must be one value or one per row ({n}), got shape {shape}")
    return np.array([check_command(x) for x in list(value)])


class Commands:
    """The commanded speeds of N rows, their next resampling times and who set them.

    ``goal``: the drawn or set commands; ``ramped``: where the ramp has brought them (the
    goals without a ramp); ``v``: the held commands, ``ramped`` with the deadband applied
    (what the observation, the reward and ``info`` see).
    """

    def __init__(self, n: int, settings: CommandSettings):
        """Commands of ``n`` rows, drawn as ``settings`` says."""
        self.s = settings
        self.v = np.zeros(n)
        self.goal = np.zeros(n)
        self.ramped = np.zeros(n)
        self.t_last = np.zeros(n)
        self.next_t = np.full(n, np.inf)

    def _draw(self, rng) -> float:
        s = self.s
        if rng.random() < s.zero_fraction:
            return 0.0
        lo, hi = s.range
        return lo if lo == hi else float(rng.uniform(lo, hi))

    def _follow(self, rows, step=None) -> None:
        """Bring the ``rows``' ramped commands toward their goals and hold them (the deadband).

        ``step`` [m/s] per row: at most that far; None: all the way.
        """
        goal, ramped = self.goal[rows], self.ramped[rows]
        if step is not None:
            gap = goal - ramped
            goal = np.where(np.abs(gap) <= step, goal, ramped + np.sign(gap) * step)
        self.ramped[rows] = goal
        self.v[rows] = np.where(np.abs(goal) < self.s.deadband, 0.0, goal)

    def _next(self, rng, t: float) -> float:
        if self.s.resample_s is None:
            return np.inf
        lo, hi = self.s.resample_s
        return t + (lo if lo == hi else float(rng.uniform(lo, hi)))

    def start(self, idx, rngs, t, given: float | np.ndarray | None = None) -> None:
        """New episodes in rows ``idx`` at times ``t`` (row ``idx[k]`` drawing from ``rngs[k]``).

        ``given``: the command of ``reset(options={"command": v})``, one or one per row of
        ``idx``, held (nothing drawn).
        """
        idx = np.asarray(idx)
        if given is not None:
            given = np.broadcast_to(np.asarray(given, dtype=np.float64), idx.shape)
        for k, i in enumerate(idx):
            if given is None:
                self.goal[i] = self._draw(rngs[k])
                self.next_t[i] = self._next(rngs[k], float(t[k]))
            else:
                self.goal[i], self.next_t[i] = given[k], np.inf
            self.t_last[i] = float(t[k])
        self._follow(idx)

    def set(self, values, rows=None) -> np.ndarray:
        """Set the commands of ``rows`` (default all) [m/s]; they hold until the next reset.

        Returns the rows' held commands (0 inside the deadband).
        """
        rows = np.arange(self.v.shape[0]) if rows is None else np.asarray(rows)
        vals = np.broadcast_to(np.asarray(values, dtype=np.float64), rows.shape)
        self.goal[rows] = [check_command(float(x)) for x in vals]
        self.next_t[rows] = np.inf
        if self.s.ramp_m_s2 is None:  # a ramp moves them before each period
            self._follow(rows)
        return self.v[rows].copy()

    def before_period(self, t: np.ndarray, rngs, rows) -> None:
        """The commands of ``rows`` at their times ``t`` (n,) before a period.

        Those due are resampled, each from its row's generator; then the ramp's step.
        """
        due = [i for i in rows if t[i] + 1e-12 >= self.next_t[i]]
        for i in due:
            self.goal[i] = self._draw(rngs[i])
            self.next_t[i] = self._next(rngs[i], float(t[i]))
        if self.s.ramp_m_s2 is None:
            if due:
                self._follow(due)
        else:
            rows = np.asarray(rows)
            self._follow(rows, self.s.ramp_m_s2 * np.maximum(t[rows] - self.t_last[rows], 0.0))
            self.t_last[rows] = t[rows]

    def features(self) -> np.ndarray:
        """(n, 1): the commanded speeds [m/s] (the observation's last entry)."""
        return self.v[:, None]


def command_cadence_term(r, p) -> np.ndarray:
    """The contact clock against targets stretched at slow commands; 1 at a zero command."""
    moving = p.command > 0.0
    speed = r.targets["speed"]
    stretch = np.where(moving, np.minimum(MAX_STRETCH, speed / np.where(moving, p.command, 1.0)),
                       1.0)  # fmt: skip
    stretch = np.maximum(stretch, 1.0)
    over = np.maximum(p.model_time_s - cadence_targets(r, p, stretch), 0.0)
    return np.where(moving, kernel(r, "cadence", over), 1.0)


STAND_MODEL = 4
"""The contact state a zero command pays for holding still in: both feet down (model 4)."""
STEP_TO_STAND = 0.5
"""What the speed term pays at a zero command in models 1-3 (a fraction of its weight): the
step under way may finish into model 4, where standing still pays up to the whole weight."""


def command_speed_term(r, p) -> np.ndarray:
    """The hip speed against the command; at a zero command, standing still in model 4.

    At a zero command, model 4 (both feet down) pays the kernel of the hip speed (standing
    still: the whole weight) and models 1-3 :data:`STEP_TO_STAND`: a walk stops by finishing
    its step into double support, not by braking on one foot (which tips the flat foot back
    or puts the raised heel down, both out of the four models).
    """
    moving = p.command != 0.0
    still = np.where(p.modes == STAND_MODEL, kernel(r, "speed", p.speed), STEP_TO_STAND)
    walk = speed_term(r, p) if p.avg_speed is None else kernel(r, "speed", p.avg_speed - p.command)
    return np.where(moving, walk, still)


def command_effort_term(r, p) -> np.ndarray:
    """The torques' size: the kernel of sum((tau / the default torque limit)^2)."""
    return kernel(r, "effort", np.sqrt(p.tau_sq) / TORQUE_LIMIT_NM)


def command_still_term(r, p) -> np.ndarray:
    """At a zero command, the kernel of the period's mean hip speed in every model; else 0."""
    return np.where(p.command == 0.0, kernel(r, "still", p.speed), 0.0)


def _unrecorded(r, value, term: str, what: str) -> bool:
    """Whether a term's input ``value`` is missing (None); refused while the term is on."""
    if value is not None:
        return False
    if r.weights[term]:
        raise ValueError(f"the {term} term needs {what}")
    return True


def command_hold_term(r, p) -> np.ndarray:
    """At a zero command, the kernel of the speed of a period spent wholly in model 4; else 0.

    A period spent wholly in model 4 ends in it with no model switch (a period that entered
    model 4 made one; one that left it ends elsewhere). The walk enters model 4 fast (about
    1.5 m/s at the hip after a 1.0 m/s walk), where the speed term's kernel pays less than the
    other models' fixed half weight: this term pays for staying in double support, braking.
    """
    if _unrecorded(r, p.switches, "hold", "the period's model switches"):
        return np.zeros_like(p.speed)
    held = (p.command == 0.0) & (p.modes == STAND_MODEL) & (p.switches == 0)
    return np.where(held, kernel(r, "hold", p.speed), 0.0)


LOAD_SCALE_N = 100.0
"""The load term's force scale [N] (the model weighs 49 N)."""


def command_load_term(r, p) -> np.ndarray:
    """At a zero command, the kernel of min(0, f_n - target) / 100 N at a model-4 period's start.

    0 elsewhere. The target [N] (0 by default) asks for a margin: a force that only just
    holds at the period's start falls below 0 within it as the body moves over the new foot.

    ``p.contact_fn``: the old stance toe's normal force at the start of each row's period
    under its torques, NaN where the period did not start in model 4
    (:meth:`CommandReward.start_toe_force`).
    """
    if _unrecorded(r, p.contact_fn, "load", "the periods' starting contact forces"):
        return np.zeros_like(p.speed)
    on = (p.command == 0.0) & ~np.isnan(p.contact_fn)
    short = np.minimum(np.where(on, p.contact_fn, 0.0) - r.targets["load"], 0.0)
    return np.where(on, kernel(r, "load", short / LOAD_SCALE_N), 0.0)


def command_steps_term(r, p) -> np.ndarray:
    """The steps completed, each paid min(1, command / speed target) (none at zero)."""
    return np.clip(p.command / r.targets["speed"], 0.0, 1.0) * p.steps


REWARD_KINDS["command"] = (
    RewardTerm("speed", 0.4, 4.0, target=1.1, value=command_speed_term, gated=True,
               doc="kernel of (the period's mean hip speed - the command [m/s])^2; at a zero "
                   "command the kernel of the hip speed in model 4 and 0.5 in models 1-3; the "
                   "target: the speed the cadence targets are made for"),
    RewardTerm("height", 0.2, 50.0, target=2.95, value=height_term, gated=True,
               doc="kernel of (hip height - target [m])^2"),
    RewardTerm("swing", 0.2, 1.0, value=swing_term, gated=True,
               doc="models 1, 2: kernel of min(0, swing ankle speed - the command [m/s])^2; "
                   "models 3, 4: the weight"),
    RewardTerm("cadence", 0.2, 50.0, target=(0.6, 0.25, 0.15, 0.1), per_model=True,
               value=command_cadence_term, gate=True,
               doc="kernel of max(0, time in the model - target x stretch [s])^2, stretched at "
                   "slow commands; the weight at a zero command"),
    RewardTerm("step", 10.0, value=command_steps_term, per_period=False,
               doc="weight x min(1, command / speed target) per step"),
    RewardTerm("effort", 0.0, 2.0, value=command_effort_term,
               doc="kernel of sum((tau / 150 N m)^2), the torques' size (weight 0: off)"),
    RewardTerm("still", 0.0, 4.0, value=command_still_term,
               doc="at a zero command, the kernel of (the period's mean hip speed [m/s])^2 in "
                   "every model, slowing paid on the way to a stop (weight 0: off)"),
    RewardTerm("load", 0.0, 0.1, target=0.0, value=command_load_term,
               doc="at a zero command, a period starting in model 4: the kernel of "
                   "(min(0, the old stance toe's normal force at its start - target [N]) / "
                   "100 N)^2 (weight 0: off)"),
    RewardTerm("hold", 0.0, 0.25, value=command_hold_term,
               doc="at a zero command, the kernel of (the period's mean hip speed [m/s])^2 in a "
                   "period spent wholly in model 4: braking in double support (weight 0: off)"),
)  # fmt: skip
COMMAND_TERMS = tuple(t.name for t in REWARD_KINDS["command"])
"""The command reward's terms, in order."""


class CommandReward(GaitReward):
    """The command reward of N rows (see the module docstring).

    The gait machinery over the command's terms, each period against the command it ran under.
    """

    KIND = "command"

    def __init__(self, reward, dt: float, n: int):
        """As :class:`~.gait.GaitReward`, with the rows' average speeds (``speed_window_s``)."""
        super().__init__(reward, dt, n)
        self.window_s = reward.speed_window_s
        self.avg = np.zeros(n)
        """The rows' hip speeds averaged over ``window_s`` [m/s] (where it is set)."""
        self._fresh = np.ones(n, dtype=bool)

    def start(self, idx) -> None:
        """Rows ``idx`` start: their averages begin at their first period's mean speed."""
        self._fresh[idx] = True

    def average_speed(self, progress_m: np.ndarray, skip=None) -> np.ndarray | None:
        """(n,): the rows' averaged hip speeds after a period (None without a window).

        avg += (1 - exp(-dt / window)) (progress / dt - avg), begun at a row's first period's
        mean speed; rows in ``skip`` (not stepped) keep theirs.
        """
        if self.window_s is None:
            return None
        speed = progress_m / self.dt
        rate = -np.expm1(-self.dt / self.window_s)
        new = np.where(self._fresh, speed, self.avg + rate * (speed - self.avg))
        stepped = np.ones(len(new), dtype=bool)
        if skip is not None:
            stepped[skip] = False
        self.avg = np.where(stepped, new, self.avg)
        self._fresh &= ~stepped
        return self.avg

    @staticmethod
    def start_toe_force(core) -> np.ndarray:
        """(n,): the old stance toe's normal force [N] in model 4 under the period's torques.

        The torques: ``core.buf.act``, clipped to the torque limit; NaN in other models.

        The force the model-4 guard reads (it switches to model 1 at f_n <= 0), from the same
        compiled solve the simulator uses, with each row's own robot (model randomisation).
        """
        if not core.action_part.holds_torques:
            raise ValueError("the load term needs torque actions (action='torque')")
        buf, sim = core.buf, core.sim
        out = np.full(core.n, np.nan)
        iopt, fopt, _, _ = core.settings.physics.options.packed
        limit = core.action_part.check_bound
        tau6 = np.zeros(N_LINKS)
        for i in np.flatnonzero(sim.ist[:, ST_MODE] == STAND_MODEL):
            if not np.all(np.isfinite(buf.act[i])):
                continue
            side = int(sim.ist[i, ST_SIDE])
            tau6[1:] = np.clip(buf.act[i], -limit, limit)
            _, forces, _, _ = nb_evaluate(buf.chs[i, side], buf.scs[i, side], STAND_MODEL, sim.q[i],
                                          sim.qd[i], tau6, 0.0, iopt, fopt, 0.0)  # fmt: skip
            out[i] = forces[FC_CONTACT]
        return out
