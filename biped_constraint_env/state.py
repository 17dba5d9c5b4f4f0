"""The simulator's state, as immutable snapshots and as arrays.

SimState, Event and StepResult for the Python API; SimArrays, N states in array form, with the
layout constants of those arrays that the compiled loop reads and writes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .hybrid import (
    N_FORCES,
)
from .model import N_LINKS
from .modes import MODE_TABLE, EventCode, Mode

MAX_EVENTS = 16
"""Capacity of the per-control-period event buffer."""
EV_T, EV_CODE, EV_FROM, EV_TO, EV_TERMINAL = range(5)
ST_MODE, ST_SIDE, ST_STEPS, ST_IGNORED = range(4)
FS_T, FS_ROOT, FS_H, FS_WORK_POS, FS_WORK_ABS, FS_DAMPED = range(6)
N_FST = 6
"""Float state: time [s], root position [m], next step [s]; then, summed over every physics
step since the start, the motors' positive work, their absolute work and the energy the joint
damping dissipated [J] (:func:`~.advance.nb_advance_w`)."""
STATUS_OK, STATUS_TERMINATED, STATUS_NONFINITE = 0, 1, 2


class SimulationError(RuntimeError):
    """The simulation produced a non-finite state; ``state`` is the last finite one."""

    def __init__(self, message: str, state: SimState, tau: np.ndarray | None = None):
        """Store the last finite state and the torques that were applied."""
        super().__init__(message)
        self.state = state
        self.tau = tau


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class SimState:
    """Everything needed to continue a simulation (immutable).

    Attributes:
        t: simulated time [s].
        mode: current paper model (1-4).
        stance_side: which physical leg stands (0 = leg A, the paper's numbering; 1 = leg B).
        q: (6,) joint angles (theta0, q1..q5) [rad] in the current numbering (docs/conventions.md).
        qd: (6,) joint rates [rad/s].
        root_y: world y of the chain root, the stance toe [m].
        steps_completed: completed walking steps (cycles 1->2->3->4->1).
        recorded_violations: bitmask of force events already recorded in this model phase
            (``lenient`` mode only; bit k = EventCode k).
        next_step_s: the error controller's next step [s] (``"rk4_limex_adaptive"``; 0 = the
            longest step), so that a run continued from this state takes the same steps.
    """

    t: float
    mode: Mode
    stance_side: int
    q: np.ndarray
    qd: np.ndarray
    root_y: float = 0.0
    steps_completed: int = 0
    recorded_violations: int = 0
    next_step_s: float = 0.0

    def __post_init__(self) -> None:
        """Validate shapes and values; freeze the arrays."""
        object.__setattr__(self, "mode", Mode(int(self.mode)))
        if self.stance_side not in (0, 1):
            raise ValueError(f"stance_side must be 0 or 1, got {self.stance_side!r}")
        for name in ("q", "qd"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != (N_LINKS,):
                raise ValueError(f"{name} must have shape ({N_LINKS},), got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be finite, got {a}")
            object.__setattr__(self, name, _frozen(a))
        for name in ("t", "root_y"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")
        if not (np.isfinite(self.next_step_s) and self.next_step_s >= 0.0):
            raise ValueError(f"next_step_s must be finite and >= 0, got {self.next_step_s!r}")

    @property
    def spec(self):
        """The :class:`~biped_constraint_env.modes.ModeSpec` of the current model."""
        return MODE_TABLE[self.mode]


class Event(NamedTuple):
    """Something that happened inside a control period."""

    t: float
    """Time of the event [s]."""
    code: EventCode
    """What happened (MODE_SWITCH or a named out-of-model event)."""
    mode_from: int
    """Model before the event."""
    mode_to: int
    """Model after the event (equal to mode_from for out-of-model events)."""
    terminal: bool
    """Whether the event ended the run."""


class StepResult(NamedTuple):
    """Outcome of :func:`step`."""

    state: SimState
    """State at the end of the control period (or at the terminal event)."""
    events: tuple[Event, ...]
    """Model switches and out-of-model events inside the period, in time order."""
    terminated: bool
    """Whether an out-of-model event ended the run."""
    termination: EventCode | None
    """The terminal event, if any."""
    forces: np.ndarray
    """(5,) contact forces at the end state: stance toe, stance heel, point contact f_n,
    stance horizontal force [N], point-contact slip speed [m/s]."""


def events_from_buffer(ev: np.ndarray, nev: int) -> tuple[Event, ...]:
    """Decode the first ``nev`` rows of an event buffer."""
    return tuple(
        Event(float(r[0]), EventCode(int(r[1])), int(r[2]), int(r[3]), bool(r[4])) for r in ev[:nev]
    )


class SimArrays:
    """N simulator states in array form, stepped together by one compiled call.

    The environments keep their state here (no per-step object construction); :meth:`get`
    and :meth:`set` convert to and from :class:`SimState`. The physics is the same
    :func:`nb_advance_w` that :func:`step` runs.
    """

    def __init__(self, n: int):
        """Allocate arrays for ``n`` simulators."""
        self.n = int(n)
        self.q = np.zeros((n, N_LINKS))
        self.qd = np.zeros((n, N_LINKS))
        self.ist = np.zeros((n, 4), np.int64)
        self.fst = np.zeros((n, N_FST))
        self.events = np.zeros((n, MAX_EVENTS, 5))
        self.n_events = np.zeros(n, np.int64)
        self.forces = np.zeros((n, N_FORCES))
        self.status = np.zeros(n, np.int64)

    def set(self, i: int, state: SimState, forces: np.ndarray | None = None) -> None:
        """Store ``state`` in slot i (status reset to running)."""
        self.q[i] = state.q
        self.qd[i] = state.qd
        self.ist[i] = (
            int(state.mode),
            state.stance_side,
            state.steps_completed,
            state.recorded_violations,
        )
        self.fst[i] = 0.0  # the work sums start with the episode
        self.fst[i, :3] = (state.t, state.root_y, state.next_step_s)
        self.status[i] = STATUS_OK
        self.n_events[i] = 0
        self.forces[i] = 0.0 if forces is None else forces

    def get(self, i: int) -> SimState:
        """The state in slot i as a :class:`SimState`."""
        return SimState(
            t=float(self.fst[i, FS_T]),
            mode=Mode(int(self.ist[i, ST_MODE])),
            stance_side=int(self.ist[i, ST_SIDE]),
            q=self.q[i],
            qd=self.qd[i],
            root_y=float(self.fst[i, FS_ROOT]),
            steps_completed=int(self.ist[i, ST_STEPS]),
            recorded_violations=int(self.ist[i, ST_IGNORED]),
            next_step_s=float(self.fst[i, FS_H]),
        )

    def events_of(self, i: int) -> tuple[Event, ...]:
        """The events of slot i's last control period."""
        return events_from_buffer(self.events[i], int(self.n_events[i]))
