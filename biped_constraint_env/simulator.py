"""The hybrid simulator's Python API: the only place that advances time.

``step(params, state, tau, dt) -> StepResult`` integrates the current model with the chosen
integrator and substeps, evaluates the guards after every substep, locates a guard crossing
inside the substep by root-finding (Illinois regula falsi, to ``time_tol_s``) or, in the
paper's manner, switches at the end of the substep; applies the reset map (impact,
renumbering) and goes on in the successor model until the control period ``dt`` is over or a
state outside the four models is reached.

The simulator is split by job: :mod:`.state` (SimState, Event, StepResult, SimArrays),
:mod:`.options` (SimOptions, presets), :mod:`.stepper` (one integration step, its error
control, event location) and :mod:`.advance` (the compiled loop of a control period,
:func:`~.advance.nb_advance`, and of N simulators, :func:`~.advance.nb_advance_batch`, used by
the batched vector environment); this module is the Python API over them. The simulator never
draws random numbers, reads the clock or logs.
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np

from .advance import PARALLEL_MIN_BATCH, nb_advance, nb_advance_batch, nb_advance_batch_parallel
from .hybrid import (
    N_FORCES,
    nb_evaluate,
)
from .kinematics import KEYPOINT_NAMES, nb_keypoints
from .model import N_ACTUATED, N_LINKS, BipedParams
from .modes import EventCode, Mode
from .options import DEFAULT_OPTIONS, FAST_OPTIONS, FIXED_STEP_OPTIONS, PAPER_OPTIONS, SimOptions
from .state import (
    FS_H,
    FS_ROOT,
    FS_T,
    MAX_EVENTS,
    N_FST,
    ST_IGNORED,
    ST_MODE,
    ST_SIDE,
    ST_STEPS,
    STATUS_NONFINITE,
    STATUS_TERMINATED,
    Event,
    SimArrays,
    SimState,
    SimulationError,
    StepResult,
    events_from_buffer,
)
from .stepper import nb_integrate

__all__ = [
    "DEFAULT_OPTIONS",
    "FAST_OPTIONS",
    "FIXED_STEP_OPTIONS",
    "PAPER_OPTIONS",
    "Event",
    "SimArrays",
    "SimOptions",
    "SimState",
    "SimulationError",
    "StepResult",
    "advance",
    "evaluate",
    "integrate_mode",
    "keypoints",
    "rollout",
    "step",
]
"""The simulator's Python API (the compiled core lives in :mod:`.stepper` and
:mod:`.advance`; state and options in :mod:`.state` and :mod:`.options`)."""


def _tau_table(tau) -> np.ndarray:
    a = np.asarray(tau, dtype=np.float64)
    if a.shape == (N_ACTUATED,):
        a = np.broadcast_to(a, (4, N_ACTUATED))
    elif a.shape != (4, N_ACTUATED):
        raise ValueError(f"tau must have shape (5,) or (4, 5), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"tau must be finite, got {a}")
    return np.ascontiguousarray(a)


def step(
    params: BipedParams,
    state: SimState,
    tau,
    dt: float,
    options: SimOptions = DEFAULT_OPTIONS,
) -> StepResult:
    """Advance the hybrid system by one control period.

    Args:
        params: the robot.
        state: the current state.
        tau: (5,) joint torques [N m] (signs of docs/conventions.md, current numbering), held
            over dt; or (4, 5), one row per model (the torque switches with the model, as in
            Table 2).
        dt: control period [s], > 0.
        options: numerics and modelling options.

    Returns:
        The :class:`StepResult`.

    Raises:
        ValueError: non-finite or wrong-shape torques, or a bad dt.
        SimulationError: the state became non-finite (carries the last finite state).
    """
    table = _tau_table(tau)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    chs, scs = params.packed
    iopt, fopt, a, b = options.packed
    q = state.q.copy()
    qd = state.qd.copy()
    ist = np.array(
        [int(state.mode), state.stance_side, state.steps_completed, state.recorded_violations],
        np.int64,
    )
    fst = np.zeros(N_FST)
    fst[:3] = (state.t, state.root_y, state.next_step_s)
    ev = np.zeros((MAX_EVENTS, 5))
    forces = np.zeros(N_FORCES)
    status, nev = nb_advance(
        chs, scs, q, qd, ist, fst, table, float(dt), iopt, fopt, a, b, ev, forces
    )
    events = events_from_buffer(ev, nev)
    new_state = (
        SimState(
            t=float(fst[FS_T]),
            mode=Mode(int(ist[ST_MODE])),
            stance_side=int(ist[ST_SIDE]),
            q=q,
            qd=qd,
            root_y=float(fst[FS_ROOT]),
            steps_completed=int(ist[ST_STEPS]),
            recorded_violations=int(ist[ST_IGNORED]),
            next_step_s=float(fst[FS_H]),
        )
        if status != STATUS_NONFINITE
        else None
    )
    if status == STATUS_NONFINITE:
        raise SimulationError(
            f"non-finite state after t = {fst[FS_T]:.6f} s in model {int(ist[ST_MODE])}",
            SimState(
                float(fst[FS_T]),
                Mode(int(ist[ST_MODE])),
                int(ist[ST_SIDE]),
                q,
                qd,
                float(fst[FS_ROOT]),
                int(ist[ST_STEPS]),
                int(ist[ST_IGNORED]),
                float(fst[FS_H]),
            ),
            table,
        )
    termination = next((e.code for e in events if e.terminal), None)
    return StepResult(new_state, events, status == STATUS_TERMINATED, termination, forces)


def keypoints(params: BipedParams, state: SimState) -> dict[str, np.ndarray]:
    """World positions [m] of the toes, heels, ankles, knees and hip, by name."""
    ch = params.chain(state.stance_side)
    pts = nb_keypoints(ch.packed, ch.packed_scalars, state.q, state.root_y)
    return {name: pts[i].copy() for i, name in enumerate(KEYPOINT_NAMES)}


def evaluate(params: BipedParams, state: SimState, tau, options: SimOptions = DEFAULT_OPTIONS):
    """Solve the current model at ``state``: (qdd (6,), forces (5,), guards (9,)).

    ``tau`` is (5,) or (4, 5) as in :func:`step` (the current model's row is used).
    """
    table = _tau_table(tau)
    tau6 = np.zeros(N_LINKS)
    tau6[1:] = table[int(state.mode) - 1]
    ch = params.chain(state.stance_side)
    iopt, fopt, _, _ = options.packed
    qdd, forces, guards, _ = nb_evaluate(
        ch.packed,
        ch.packed_scalars,
        int(state.mode),
        state.q,
        state.qd,
        tau6,
        state.root_y,
        iopt,
        fopt,
        0.0,
    )
    return qdd, forces, guards


def rollout(
    params: BipedParams,
    state: SimState,
    tau,
    dt: float,
    n_steps: int,
    options: SimOptions = DEFAULT_OPTIONS,
) -> tuple[list[SimState], list[Event], EventCode | None]:
    """Apply the same torques for up to ``n_steps`` control periods (stops at a terminal event).

    Returns the states (the initial one first), all events, and the terminal event or None.
    """
    states = [state]
    events: list[Event] = []
    for _ in range(int(n_steps)):
        res = step(params, states[-1], tau, dt, options)
        states.append(res.state)
        events.extend(res.events)
        if res.terminated:
            return states, events, res.termination
    return states, events, None


def integrate_mode(
    params: BipedParams,
    state: SimState,
    tau,
    h: float,
    options: SimOptions = DEFAULT_OPTIONS,
) -> SimState:
    """One integration step of length h [s] inside the current model, with no guards.

    For studies of the integrators alone (convergence, stability); :func:`step` is the
    simulator. Raises SimulationError on a non-finite result.
    """
    table = _tau_table(tau)
    if not (np.isfinite(h) and h > 0):
        raise ValueError(f"h must be finite and > 0, got {h!r}")
    tau6 = np.zeros(N_LINKS)
    tau6[1:] = table[int(state.mode) - 1]
    ch = params.chain(state.stance_side)
    iopt, fopt, a, b = options.packed
    q1, qd1 = nb_integrate(
        ch.packed,
        ch.packed_scalars,
        int(state.mode),
        state.q.copy(),
        state.qd.copy(),
        tau6,
        float(h),
        iopt,
        fopt,
        a,
        b,
    )
    if not (np.all(np.isfinite(q1)) and np.all(np.isfinite(qd1))):
        raise SimulationError(f"non-finite state after one step of {h} s", state, table)
    return dataclasses.replace(state, t=state.t + h, q=q1, qd=qd1)


def advance(
    params: BipedParams,
    arrays: SimArrays,
    tau_tables: np.ndarray,
    dt: float,
    options: SimOptions = DEFAULT_OPTIONS,
) -> None:
    """Advance every running slot of ``arrays`` by dt [s] under ``tau_tables`` (n, 4, 5) [N m].

    Slots whose status is not 0 (terminated or non-finite) are left as they are. Inputs are
    the caller's responsibility (the environments validate actions); the torques must be finite.
    """
    chs, scs = params.packed
    iopt, fopt, a, b = options.packed
    args = (
        chs,
        scs,
        arrays.q,
        arrays.qd,
        arrays.ist,
        arrays.fst,
        tau_tables,
        float(dt),
        iopt,
        fopt,
        a,
        b,
        arrays.events,
        arrays.forces,
        arrays.status,
        arrays.n_events,
    )
    if arrays.n >= PARALLEL_MIN_BATCH and numba.get_num_threads() > 1:  # (n checked first: cheap)
        nb_advance_batch_parallel(*args, numba.get_num_threads())
    else:
        nb_advance_batch(*args)
