"""Terminations: the ``termination`` part, its settings and the learning task's named list.

The strict checks' out-of-model events and the fall height (``fall_hip_height_m``) end an
episode inside the compiled period, and ``time_limit_s`` truncates it by simulated time; the
learning task's own early terminations are named here (:data:`TERMINATIONS`), each switched on
by its key in the ``termination`` dict, and run by the core after a period in that order. A
new one is one entry here: its key's check and a class built from the core, called with the
rows the period skipped, returning the rows it ends (its ``reason`` names them in ``info``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .rewards import REC_PROGRESS, check_fall_height
from .state import FS_T
from .tasks import EPISODE_S, MAX_EPISODE_S
from .validation import check_mapping, check_real


class ModelTime:
    """``termination={"max_model_time_s": T}``: a contact phase held longer than T [s].

    By the contact clock; with a command, only the periods of the phase run under a speed
    command count (standing holds a contact phase, and a restart from it has T from the new
    command on). With ``max_first_phase_s`` also set, a start near rest's first contact phase is
    that one's (:class:`FirstPhaseTime`). Reason ``model_time``.
    """

    reason = "model_time"

    def __init__(self, core, limit_s: float):
        """For ``core``'s clock and commands (if any), and the limit [s]."""
        self.clock, self.commands, self.limit_s = core.clock, core.commands, limit_s
        self.held = np.zeros(core.n, np.int64)  # periods of the phase under a speed command
        self.rows = self._rows(core)

    def _rows(self, core):
        """Which rows the limit applies to: fn() -> (n,) bool, or None for every row."""
        if core.settings.termination.get("max_first_phase_s") is None:
            return None
        return lambda: ~self.clock.opening

    def __call__(self, skip) -> np.ndarray:
        """(n,) the stepped rows that held their contact phase too long."""
        j = self.clock.j  # periods since the phase began: 0 after a switch or a start
        held = j if self.commands is None else np.where(
            self.commands.v != 0.0, np.minimum(self.held + 1, j), 0)  # fmt: skip
        if skip is None:
            self.held = held.copy()
        else:
            stepped = np.ones(held.shape[0], bool)
            stepped[skip] = False
            self.held[stepped] = held[stepped]
        over = self.held * self.clock.dt > self.limit_s + 1e-9
        if self.rows is not None:
            over &= self.rows()
        if skip is not None:
            over[skip] = False
        return over


class FirstPhaseTime(ModelTime):
    """``termination={"max_first_phase_s": T}``: a start near rest's first contact phase too long.

    Held longer than T [s]: the phase a start begins in, until its first model switch (from
    rest: the sway on the flat foot before the first step, which takes longer than a walking
    phase); counted as :class:`ModelTime` counts. Reason ``first_phase_time``.
    """

    reason = "first_phase_time"

    def _rows(self, core):
        """The rows still in their first contact phase."""
        return lambda: self.clock.opening


STOP_SPEED_M_S = 0.1
"""The hip speed [m/s] (a period's mean, either way) that ends a zero command's episode after
its grace time (:class:`StopTime`): the command protocol's bound on every period of a stand."""


class StopTime:
    """``termination={"max_stop_s": T}``: still moving T [s] after a zero command.

    With a command, a row whose command has been zero for longer than T [s] (since it became
    zero, or the episode began at zero) and whose hip moved faster than
    :data:`STOP_SPEED_M_S` in the period: an early termination that makes walking on through
    a zero command end the episode, as the command protocol's stop asks (at rest within 3 s).
    The speed is the period's hip progress over the control period ``dt`` (the reward's
    speed; a period cut short at a model switch reads slower by its fraction) and the zero
    command's start the end of its first period less ``dt``. Reason ``stop_time``; needs a
    command (refused by the settings otherwise).
    """

    reason = "stop_time"

    def __init__(self, core, limit_s: float):
        """For ``core``'s commands and hip progress, and the grace time [s]."""
        self.core, self.limit_s, self.dt = core, limit_s, core.settings.physics.dt
        self.since = np.full(core.n, np.nan)  # the episode time the zero command began

    def __call__(self, skip) -> np.ndarray:
        """(n,) the stepped rows still moving past the grace time of their zero command."""
        core = self.core
        t = core.sim.fst[:, FS_T]  # after the period: its end
        zero = core.commands.v == 0.0
        since = np.where(zero, self.since, np.nan)
        fresh = zero & ~(since <= t - self.dt + 1e-9)  # a new zero run, or a new episode
        since[fresh] = t[fresh] - self.dt
        if skip is None:
            self.since = since
        else:
            stepped = np.ones(core.n, bool)
            stepped[skip] = False
            self.since[stepped] = since[stepped]
        speed = np.abs(core.buf.rew[:, REC_PROGRESS]) / self.dt
        over = zero & (t - self.since > self.limit_s + 1e-9) & (speed > STOP_SPEED_M_S)
        if skip is not None:
            over[skip] = False
        return over


def check_stop_time(value) -> float:
    """A zero command's grace time before moving ends the episode [s]."""
    return check_real("max_stop_s", value, 0.0, 1e3, low_open=True, unit=" [s]")


def check_model_time(value) -> float:
    """A contact phase's longest time [s]."""
    return check_real("max_model_time_s", value, 0.0, 1e3, low_open=True, unit=" [s]")


def check_first_phase_time(value) -> float:
    """The episode's first contact phase's longest time [s]."""
    return check_real("max_first_phase_s", value, 0.0, 1e3, low_open=True, unit=" [s]")


@dataclass(frozen=True)
class Termination:
    """A learning termination: its setting's check, its class and its clock.

    ``make(core, value)`` builds it; ``needs_clock``: whether it reads the contact clock.
    """

    check: Callable[[Any], Any]
    make: Callable
    needs_clock: bool = False


TERMINATIONS: dict[str, Termination] = {
    "max_model_time_s": Termination(check_model_time, ModelTime, needs_clock=True),
    "max_first_phase_s": Termination(check_first_phase_time, FirstPhaseTime, needs_clock=True),
    "max_stop_s": Termination(check_stop_time, StopTime),
}
"""The learning task's terminations by their ``termination`` key, in the order they run."""
BUILT_IN = ("fall_hip_height_m", "time_limit_s")
"""The ``termination`` keys of the compiled fall and of the truncation by simulated time."""


@dataclass(frozen=True)
class TerminationSettings:
    """What ends an episode besides the strict checks.

    A fall height [m] (None: off), the time limit [s] (None: none) and the learning
    terminations switched on ((key, value), ...).
    """

    fall_hip_height_m: float | None = None
    time_limit_s: float | None = EPISODE_S
    learning: tuple[tuple[str, Any], ...] = ()

    def get(self, key: str) -> Any:
        """The value of a learning termination's key (None: off)."""
        return dict(self.learning).get(key)

    @property
    def needs_clock(self) -> bool:
        """Whether a termination on reads the contact clock."""
        return any(TERMINATIONS[k].needs_clock for k, _ in self.learning)

    def as_dict(self) -> dict[str, Any]:
        """The settings as data: every key of the ``termination`` dict, None where off."""
        return {"fall_hip_height_m": self.fall_hip_height_m, "time_limit_s": self.time_limit_s,
                **{k: self.get(k) for k in TERMINATIONS}}  # fmt: skip


def termination_keys() -> tuple[str, ...]:
    """Every key the ``termination`` dict takes."""
    return (*BUILT_IN, *TERMINATIONS)


def termination_settings(spec: Any) -> TerminationSettings:
    """The ``termination`` kwarg: a dict of :func:`termination_keys` (None: the defaults)."""
    t = dict(check_mapping("termination", {} if spec is None else spec, termination_keys()))
    limit = t.get("time_limit_s", EPISODE_S)
    return TerminationSettings(
        fall_hip_height_m=check_fall_height(t.get("fall_hip_height_m")),
        time_limit_s=None if limit is None else check_real(
            "time_limit_s", limit, 0.0, MAX_EPISODE_S, low_open=True, unit=" [s]"),
        learning=tuple((k, TERMINATIONS[k].check(t[k])) for k in TERMINATIONS
                       if t.get(k) is not None),
    )  # fmt: skip


def terminations(core) -> list:
    """The learning terminations ``core``'s settings switch on, built, in order."""
    return [TERMINATIONS[k].make(core, v) for k, v in core.settings.termination.learning]
