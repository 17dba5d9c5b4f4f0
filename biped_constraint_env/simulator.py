"""The hybrid simulator: the only place that advances time.

``step(params, state, tau, dt) -> StepResult`` integrates the current model with the chosen
integrator and substeps, evaluates the guards after every substep, locates a guard crossing
inside the substep by root-finding (Illinois regula falsi, to ``time_tol_s``) or, in the
paper's manner, switches at the end of the substep; applies the reset map (impact,
renumbering) and goes on in the successor model until the control period ``dt`` is over or a
state outside the four models is reached.

The whole loop is one compiled function (:func:`nb_advance`); :func:`nb_advance_batch` runs it
over N independent simulators in one call (used by the batched vector environment).
The simulator never draws random numbers, reads the clock or logs.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np
from numba import njit

from .contact import nb_slip_sign
from .hybrid import (
    CONTACT_COL,
    FC_SLIP,
    FO_POS_TOL,
    FO_SLIP_EPS,
    FO_STEP_TOL,
    FO_TIME_TOL,
    IMPACT_PAPER,
    IMPACT_PLASTIC,
    IO_FOOT_WEIGHT,
    IO_IMPACT,
    IO_INTEGRATOR,
    IO_JDOT_FD,
    IO_LOCATE,
    IO_MASS_RNEA,
    IO_MAX_SWITCHES,
    IO_PROJECT,
    IO_STOP_AT_SWITCH,
    IO_STRICT,
    IO_SUBSTEPS,
    N_FOPT,
    N_FORCES,
    N_IOPT,
    W_QDD,
    nb_carve,
    nb_evaluate,
    nb_evaluate_w,
    nb_impact,
    nb_make_work,
    nb_project_w,
    nb_renumber,
    nb_solve_mode_w,
)
from .integrators import (
    EVALS_PER_STEP,
    Integrator,
    friction_is_stiff,
    parse_integrator,
    tableau,
)
from .jit import njit_alloc, njit_noalloc
from .kinematics import KEYPOINT_NAMES, nb_keypoints
from .model import N_ACTUATED, N_LINKS, BipedParams
from .modes import FORCE_EVENTS, MODE_TABLE, N_GUARDS, EventCode, Mode, packed_mode_table
from .validation import check_bool, check_choice, check_int, check_real

MAX_EVENTS = 16
"""Capacity of the per-control-period event buffer."""
EV_T, EV_CODE, EV_FROM, EV_TO, EV_TERMINAL = range(5)
ST_MODE, ST_SIDE, ST_STEPS, ST_IGNORED = range(4)
FS_T, FS_ROOT, FS_H = range(3)
N_FST = 3
STATUS_OK, STATUS_TERMINATED, STATUS_NONFINITE = 0, 1, 2
MAX_LOCATE_ITERATIONS = 100
"""Safety cap on root-finding iterations (the tolerance is normally met in < 20)."""
H_MIN_S = 1e-6
"""Smallest error-controlled step [s]: a step this short is accepted whatever its estimate,
and no step is proposed shorter (so that a period takes at most about dt / H_MIN_S steps)."""
STEP_TOL_MIN = 1e-10
"""Smallest accepted ``step_tol`` (below it every step would be H_MIN_S anyway)."""
RATE_ERROR_WEIGHT_S = 0.05
"""How a rate error counts in the error-controlled step's estimate: as the angle [rad] it
moves a link over this time [s] (or over the step, if longer). Rates matter beyond the angles
they move: a controller observes them every period. At 5 ms control the walking network's
outcomes on seeds 0-9 agree with those under fixed 2.5 ms steps (and 0.31 ms, seeds 0 and 4)
when the estimate per step stays below 2e-4 rad and 4e-3 rad/s; with rates weighted by the
step alone (5 ms, 4e-2 rad/s) they do not (a 36th step in most episodes, a fall in one;
docs/speed_accuracy.md)."""
EVENT_STEP_FRACTION = 0.1
"""The error-controlled first step after a model switch, as a fraction of the largest step:
an impact starts fast transients (the new contact's slip, the damped joints), which a step
sized for the motion before it would only meet with rejections."""

_RF, _CT, _GD, _SU, _RS = packed_mode_table()
SUCCESSOR = tuple(int(x) for x in _SU)
RESET = tuple(int(x) for x in _RS)
FORCE_EVENT_FLAGS = tuple(int(EventCode(k) in FORCE_EVENTS) for k in range(N_GUARDS))
N_STAGES = tuple(EVALS_PER_STEP[Integrator(m)] for m in range(len(Integrator)))
SEMI_IMPLICIT = int(Integrator.SEMI_IMPLICIT)
LIMEX = int(Integrator.LIMEX)
RK4_LIMEX = int(Integrator.RK4_LIMEX)
RK4_LIMEX_ADAPTIVE = int(Integrator.RK4_LIMEX_ADAPTIVE)
EVENT_PRIORITY = (5, 2, 3, 4, 1, 6, 7, 8)
"""Order in which simultaneous out-of-model guards are reported: geometry before forces."""


class SimulationError(RuntimeError):
    """The simulation produced a non-finite state; ``state`` is the last finite one."""

    def __init__(self, message: str, state: SimState, tau: np.ndarray | None = None):
        """Store the last finite state and the torques that were applied."""
        super().__init__(message)
        self.state = state
        self.tau = tau


MAX_SUBSTEPS = 100_000
"""Most integration steps per control period (``substeps``): 50 ns steps in a 5 ms period."""
_REAL_OPTION_RANGES = {
    "slip_eps_mps": (0.0, 1.0),
    "pos_tol_m": (0.0, 1e-2),
    "time_tol_s": (0.0, 1e-2),
    "step_tol": (STEP_TOL_MIN, 1.0),
}
"""Accepted ranges of the real-valued options (the lower bound excluded when it is 0)."""


@dataclass(frozen=True)
class SimOptions:
    """Numerical and modelling options of the simulator (see README, Model).

    Attributes:
        integrator: ``"euler"``, ``"semi_implicit"``, ``"rk2"``, ``"rk4"``, ``"limex"``
            (linearly implicit extrapolation, L-stable, friction implicit), ``"rk4_limex"``
            (RK4, with LIMEX on the steps where the friction is stiff) or
            ``"rk4_limex_adaptive"`` (the same with error-controlled steps); module
            integrators.
        substeps: integration steps per control period (>= 1); for ``"rk4_limex_adaptive"``
            the period / substeps is the longest step.
        impact: ``"paper"`` (all joint velocities zero at 2->3 and 3->4) or ``"plastic"``.
        locate_events: locate guard crossings inside a substep (else switch at the sample).
        jdot: ``"exact"`` J-dot q-dot, or ``"finite_difference"`` (paper eq. 7-8).
        strict: end the run on force violations (else record them and go on).
        heel_force_includes_foot_weight: add the stance foot's weight in paper eq. 18-19.
        project_constraints: project the point contact onto z = 0 after every substep.
        slip_eps_mps: friction regularisation speed [m/s].
        pos_tol_m: penetration tolerated before a geometric event fires [m].
        time_tol_s: event-time tolerance of the root-finding [s].
        max_switches: model switches allowed in one control period before ZENO is declared.
        mass_matrix: ``"crba"`` (composite bodies, one pass) or ``"newton_euler_columns"``
            (the paper's route, eq. 14: six Newton-Euler passes with unit accelerations).
        stop_at_switch: end the control period early, just after the first model switch
            (its impact and renumbering applied), so that a controller can choose the new
            model's torques at the switch itself (event-driven control; the paper changes the
            torque at the switch). Off: the torque row of each model holds to the period's end.
        step_tol: error tolerance of one ``"rk4_limex_adaptive"`` step: the largest estimated
            error of an angle [rad], or of a rate [rad/s] times :data:`RATE_ERROR_WEIGHT_S`
            (50 ms; the step if longer); unused by the fixed-step integrators.
    """

    integrator: str = "rk4_limex_adaptive"
    substeps: int = 1
    impact: str = "plastic"
    locate_events: bool = True
    jdot: str = "exact"
    strict: bool = True
    heel_force_includes_foot_weight: bool = True
    project_constraints: bool = True
    slip_eps_mps: float = 1e-3
    pos_tol_m: float = 1e-9
    time_tol_s: float = 1e-7
    max_switches: int = 8
    mass_matrix: str = "crba"
    stop_at_switch: bool = False
    step_tol: float = 2e-4

    def __post_init__(self) -> None:
        """Validate every option (a ``ValueError`` names the option)."""
        if isinstance(self.integrator, (bool, float)):
            raise ValueError(f"integrator must be a name or an Integrator, got {self.integrator!r}")
        parse_integrator(self.integrator)
        check_int("substeps", self.substeps, 1, MAX_SUBSTEPS)
        check_choice("impact", self.impact, ("paper", "plastic"))
        check_choice("jdot", self.jdot, ("exact", "finite_difference"))
        for name in (
            "locate_events",
            "strict",
            "heel_force_includes_foot_weight",
            "project_constraints",
            "stop_at_switch",
        ):
            check_bool(name, getattr(self, name))
        for name, (low, high) in _REAL_OPTION_RANGES.items():
            check_real(name, getattr(self, name), low, high, low_open=low == 0.0)
        check_choice("mass_matrix", self.mass_matrix, ("crba", "newton_euler_columns"))
        check_int("max_switches", self.max_switches, 1, 1000)

    @functools.cached_property
    def packed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(iopt, fopt, A, b) arrays for the compiled core."""
        method = parse_integrator(self.integrator)
        iopt = np.zeros(N_IOPT, np.int64)
        iopt[IO_INTEGRATOR] = method
        iopt[IO_SUBSTEPS] = self.substeps
        iopt[IO_IMPACT] = IMPACT_PAPER if self.impact == "paper" else IMPACT_PLASTIC
        iopt[IO_LOCATE] = self.locate_events
        iopt[IO_JDOT_FD] = self.jdot == "finite_difference"
        iopt[IO_STRICT] = self.strict
        iopt[IO_FOOT_WEIGHT] = self.heel_force_includes_foot_weight
        iopt[IO_PROJECT] = self.project_constraints
        iopt[IO_MAX_SWITCHES] = self.max_switches
        iopt[IO_MASS_RNEA] = self.mass_matrix == "newton_euler_columns"
        iopt[IO_STOP_AT_SWITCH] = self.stop_at_switch
        fopt = np.zeros(N_FOPT)
        fopt[FO_SLIP_EPS] = self.slip_eps_mps
        fopt[FO_POS_TOL] = self.pos_tol_m
        fopt[FO_TIME_TOL] = self.time_tol_s
        fopt[FO_STEP_TOL] = self.step_tol
        a, b = tableau(method)
        for arr in (iopt, fopt, a, b):
            arr.flags.writeable = False
        return iopt, fopt, a, b

    def replace(self, **changes: object) -> SimOptions:
        """A copy with some options changed (validated)."""
        return dataclasses.replace(self, **changes)


DEFAULT_OPTIONS = SimOptions()
"""Defaults: error-controlled RK4_LIMEX (tolerance 2e-4, steps up to the control period, 5 ms
in the walking task), located events, exact J-dot, strict checks, plastic impacts, and the
heel/toe split of the flat stance foot with the foot's weight included (the exact ground
reaction, so that F_L <= 0 agrees with the model-2 dynamics). The cheapest setting of the
accuracy study meeting <= 1e-3 rad and <= 1 ms switch-time error over both walking scenes
(README, Speed and accuracy), at about 700 evaluations per simulated second."""

FIXED_STEP_OPTIONS = DEFAULT_OPTIONS.replace(integrator="rk4_limex", substeps=8)
"""RK4_LIMEX x 8 fixed substeps per 20 ms (2.5 ms): the cheapest fixed-step setting meeting the
accuracy rule (about 1,900 evaluations per simulated second), as accurate as the default and
the same cost in the walking task, where the default's steps are limited to 5 ms anyway."""

FAST_OPTIONS = DEFAULT_OPTIONS.replace(integrator="rk2", substeps=4)
"""RK2 x 4 substeps per 20 ms (5 ms, inside RK2's limit 2/lambda ~ 7.7 ms): about 3x cheaper;
7e-4 rad over the two-impact scene but 0.03 rad over the full-cycle scene (env v0)."""

PAPER_OPTIONS = SimOptions(
    integrator="euler",
    substeps=1,
    impact="paper",
    locate_events=False,
    jdot="finite_difference",
    strict=False,
    heel_force_includes_foot_weight=False,
    project_constraints=False,
)
"""The paper's numerics: explicit Euler at the sample, switch at the sample, finite-difference
J-dot, zero-velocity impacts, foot weight left out, lenient force checks, no projection."""


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


# --------------------------------------------------------------------------- compiled core


S_KQ, S_KV, S_QS, S_VS, S_Q1, S_QD1, S_QH, S_QDH, S_G, S_G1, S_TAU6, S_F, S_K1 = range(13)


@njit(cache=True)
def nb_make_scratch():
    """Scratch arrays of the stepping loop (zeroed views of one allocation)."""
    buf = np.zeros(24 + 24 + 6 * 6 + 2 * N_GUARDS + 6 + N_FORCES + 7)
    g = 84 + 2 * N_GUARDS
    return (
        nb_carve(buf, 0, 4, 6),  # kq: stage velocities
        nb_carve(buf, 24, 4, 6),  # kv: stage accelerations
        buf[48:54],  # stage q
        buf[54:60],  # stage qd
        buf[60:66],  # q after a step
        buf[66:72],  # qd after a step
        buf[72:78],  # q at the bracket's upper end (event location)
        buf[78:84],  # qd at the bracket's upper end
        buf[84 : 84 + N_GUARDS],  # guards
        buf[84 + N_GUARDS : g],  # guards after a step
        buf[g : g + 6],  # tau6
        buf[g + 6 : g + 6 + N_FORCES],  # forces scratch
        buf[g + 6 + N_FORCES : g + 13 + N_FORCES],  # qdd at the start state (first RK stage,
        # reused), slip speed
    )


@njit_noalloc
def _limex_step(ch, sc, mode, q, qd, tau6, h, fd, eps, W, S, mr):
    """One LIMEX step of h into S[S_Q1], S[S_QD1].

    y_a is one linearly implicit Euler step of h, y_b two of h / 2, and y1 = 2 y_b - y_a.
    """
    q1 = S[S_Q1]
    qd1 = S[S_QD1]
    qdd = W[W_QDD]
    qa = S[S_KQ][0]
    va = S[S_KV][0]
    qs = S[S_QS]
    vs = S[S_VS]
    nb_solve_mode_w(ch, sc, mode, q, qd, tau6, h, fd, eps, W, mr, True)
    for j in range(6):
        va[j] = qd[j] + h * qdd[j]
        qa[j] = q[j] + h * va[j]
    h2 = 0.5 * h
    nb_solve_mode_w(ch, sc, mode, q, qd, tau6, h2, 0.5 * fd, eps, W, mr, True)
    for j in range(6):
        vs[j] = qd[j] + h2 * qdd[j]
        qs[j] = q[j] + h2 * vs[j]
    nb_solve_mode_w(ch, sc, mode, qs, vs, tau6, h2, 0.5 * fd, eps, W, mr, True)
    for j in range(6):
        qd1[j] = vs[j] + h2 * qdd[j]
        q1[j] = qs[j] + h2 * qd1[j]
        qd1[j] = 2.0 * qd1[j] - va[j]
        q1[j] = 2.0 * q1[j] - qa[j]


@njit_noalloc
def nb_integrate_w(ch, sc, mode, q, qd, tau6, h, iopt, fopt, a, b, W, S, use_k1=False):
    """One integration step of length h [s] inside ``mode``; result in S[S_Q1], S[S_QD1].

    With ``use_k1`` the first explicit stage is taken from S[S_K1], the accelerations already
    evaluated at (q, qd) with the same torques (first-same-as-last reuse).
    """
    method = iopt[IO_INTEGRATOR]
    fd = h if iopt[IO_JDOT_FD] != 0 else 0.0
    eps = fopt[FO_SLIP_EPS]
    q1 = S[S_Q1]
    qd1 = S[S_QD1]
    qdd = W[W_QDD]
    used = 0
    if method == SEMI_IMPLICIT:
        used = 2
        nb_solve_mode_w(ch, sc, mode, q, qd, tau6, h, fd, eps, W, iopt[IO_MASS_RNEA] != 0)
        for j in range(6):
            qd1[j] = qd[j] + h * qdd[j]
            q1[j] = q[j] + h * qd1[j]
    elif method == LIMEX:
        used = 1
        _limex_step(ch, sc, mode, q, qd, tau6, h, fd, eps, W, S, iopt[IO_MASS_RNEA] != 0)
    else:
        ns = N_STAGES[method]
        kq = S[S_KQ]
        kv = S[S_KV]
        qs = S[S_QS]
        vs = S[S_VS]
        # stiffness switching: watch the slip sign at each stage state (start included)
        switching = (method == RK4_LIMEX or method == RK4_LIMEX_ADAPTIVE) and CONTACT_COL[mode] >= 0
        stiff = False
        s_first = 0.0
        if switching and use_k1:
            s_first = nb_slip_sign(S[S_K1][6], eps)
            stiff = friction_is_stiff(s_first, h)
        for st in range(ns):
            if stiff:
                break
            for j in range(6):
                qs[j] = q[j]
                vs[j] = qd[j]
            for k in range(st):
                c = h * a[st, k]
                if c != 0.0:
                    for j in range(6):
                        qs[j] += c * kq[k, j]
                        vs[j] += c * kv[k, j]
            if st == 0 and use_k1:
                for j in range(6):
                    kq[0, j] = qd[j]
                    kv[0, j] = S[S_K1][j]
                continue
            _, sg, _ = nb_solve_mode_w(
                ch, sc, mode, qs, vs, tau6, 0.0, fd, eps, W, iopt[IO_MASS_RNEA] != 0
            )
            if switching:
                if st == 0:
                    s_first = sg
                if friction_is_stiff(sg, h) or sg * s_first < 0.0:
                    stiff = True
                    break
            for j in range(6):
                kq[st, j] = vs[j]
                kv[st, j] = qdd[j]
        if stiff:
            used = 1
            _limex_step(ch, sc, mode, q, qd, tau6, h, fd, eps, W, S, iopt[IO_MASS_RNEA] != 0)
        else:
            for j in range(6):
                q1[j] = q[j]
                qd1[j] = qd[j]
            for st in range(ns):
                c = h * b[st]
                for j in range(6):
                    q1[j] += c * kq[st, j]
                    qd1[j] += c * kv[st, j]
    if iopt[IO_PROJECT] != 0:
        nb_project_w(ch, sc, mode, q1, qd1, W)
    elif _RF[mode] == 0:
        q1[0] = 0.0
        qd1[0] = 0.0
    return used


@njit(cache=True)
def nb_integrate(ch, sc, mode, q, qd, tau6, h, iopt, fopt, a, b):
    """Allocating form of :func:`nb_integrate_w`: returns the new (q, qd)."""
    W = nb_make_work()
    S = nb_make_scratch()
    nb_integrate_w(ch, sc, mode, q, qd, tau6, h, iopt, fopt, a, b, W, S)
    return S[S_Q1].copy(), S[S_QD1].copy()


@njit_noalloc
def _fired(g, k, ignored):
    if (ignored >> k) & 1:
        return False
    return g[k] <= 0.0 if k == 0 else g[k] < 0.0


@njit_noalloc
def _gmin(g, mask):
    v = np.inf
    for k in range(g.shape[0]):
        if (mask >> k) & 1:
            v = min(v, g[k])
    return v


@njit_noalloc
def _hermite(q0, v0, a0, q1, v1, a1, h, s, qs, vs):
    """State at s h (0 <= s <= 1) of a step (q0, v0) -> (q1, v1) of length h.

    Uses the accelerations a0, a1 at its ends: quintic Hermite in q, cubic Hermite in qd.
    """
    s2 = s * s
    s3 = s2 * s
    s4 = s3 * s
    s5 = s4 * s
    p0 = 1.0 - 10.0 * s3 + 15.0 * s4 - 6.0 * s5
    p1 = s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5
    p2 = 0.5 * (s2 - 3.0 * s3 + 3.0 * s4 - s5)
    p3 = 1.0 - p0
    p4 = -4.0 * s3 + 7.0 * s4 - 3.0 * s5
    p5 = 0.5 * (s3 - 2.0 * s4 + s5)
    c0 = 2.0 * s3 - 3.0 * s2 + 1.0
    c1 = s3 - 2.0 * s2 + s
    c2 = 1.0 - c0
    c3 = s3 - s2
    hh = h * h
    for j in range(6):
        qs[j] = p0 * q0[j] + p1 * h * v0[j] + p2 * hh * a0[j] + p3 * q1[j]
        qs[j] += p4 * h * v1[j] + p5 * hh * a1[j]
        vs[j] = c0 * v0[j] + c1 * h * a0[j] + c2 * v1[j] + c3 * h * a1[j]


@njit_noalloc
def nb_locate_w(ch, sc, mode, q, qd, tau6, h, mask, iopt, fopt, a, b, W, S, use_k1):
    """Earliest crossing in (0, h] of the guards in ``mask``; returns theta.

    On entry S[S_G] holds the guards at the start state (q, qd), S[S_Q1], S[S_QD1] and S[S_G1]
    the full step's end state and guards; on return S[S_QH], S[S_QDH] hold the state at
    theta h. Illinois regula falsi (with a bisection every fourth iteration) on
    G(theta) = min_k g_k(x(theta)), x(theta) being the integrator's step of length theta h from
    (q, qd); the bracket is closed to ``time_tol_s``.
    """
    fd = h if iopt[IO_JDOT_FD] != 0 else 0.0
    qh = S[S_QH]
    qdh = S[S_QDH]
    for j in range(6):
        qh[j] = S[S_Q1][j]
        qdh[j] = S[S_QD1][j]
    ghi = _gmin(S[S_G1], mask)
    glo = _gmin(S[S_G], mask)
    g = S[S_G1]
    fo = S[S_F]
    lo = 0.0
    hi = 1.0
    if not glo > 0.0:
        for j in range(6):
            qh[j] = q[j]
            qdh[j] = qd[j]
        return 0.0
    side = 0
    tol = fopt[FO_TIME_TOL] / h
    dense = iopt[IO_INTEGRATOR] == RK4_LIMEX_ADAPTIVE
    if dense:  # the end state and accelerations, kept for the interpolant
        for j in range(6):
            S[S_KQ][3, j] = S[S_Q1][j]
            S[S_KV][3, j] = S[S_QD1][j]
            S[S_KV][2, j] = W[W_QDD][j]
    for it in range(MAX_LOCATE_ITERATIONS):
        if hi - lo <= tol:
            break
        if it % 4 == 3:
            th = 0.5 * (lo + hi)  # a bisection now and then guarantees the bracket shrinks
        else:
            th = (lo * ghi - hi * glo) / (ghi - glo)
            th = min(max(th, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
        if dense:
            _hermite(q, qd, S[S_K1], S[S_KQ][3], S[S_KV][3], S[S_KV][2], h, th, S[S_QS], S[S_VS])
            if iopt[IO_PROJECT] != 0:
                nb_project_w(ch, sc, mode, S[S_QS], S[S_VS], W)
            xq = S[S_QS]
            xv = S[S_VS]
        else:
            nb_integrate_w(ch, sc, mode, q, qd, tau6, th * h, iopt, fopt, a, b, W, S, use_k1)
            xq = S[S_Q1]
            xv = S[S_QD1]
        nb_evaluate_w(ch, sc, mode, xq, xv, tau6, iopt, fopt, fd, W, fo, g)
        gt = _gmin(g, mask)
        if gt <= 0.0:
            hi = th
            ghi = gt
            for j in range(6):
                qh[j] = xq[j]
                qdh[j] = xv[j]
            if side == -1:
                glo *= 0.5
            side = -1
        else:
            lo = th
            glo = gt
            if side == 1:
                ghi *= 0.5
            side = 1
    return hi


@njit_noalloc
def _record(ev, nev, t, code, mfrom, mto, terminal):
    if nev < ev.shape[0]:
        ev[nev, 0] = t
        ev[nev, 1] = code
        ev[nev, 2] = mfrom
        ev[nev, 3] = mto
        ev[nev, 4] = terminal
        return nev + 1
    return nev


@njit_noalloc
def _step_error(S, W, hh, used, tol):
    """Error estimate of the step of hh [s] just taken, relative to tol (accept when <= 1).

    ``used`` 1 (a LIMEX step): half the difference between the extrapolated result and the
    single linearly implicit Euler step, i.e. the error of the two half steps (first order
    in h^2, so conservative for the second-order result). Otherwise (an RK4 step): the
    difference between RK4 and the third-order solution of the same stages plus the
    end-state evaluation, h/6 (f(y1) - k4), with no extra evaluation (the end state is
    evaluated anyway, for its guards). Angles count in rad, rates in rad/s times the larger
    of hh and :data:`RATE_ERROR_WEIGHT_S`.
    """
    q1 = S[S_Q1]
    qd1 = S[S_QD1]
    e = 0.0
    w = max(hh, RATE_ERROR_WEIGHT_S)
    if used == 1:
        qa = S[S_KQ][0]
        va = S[S_KV][0]
        for j in range(6):
            e = max(e, 0.5 * abs(q1[j] - qa[j]), 0.5 * w * abs(qd1[j] - va[j]))
    else:
        kq = S[S_KQ][3]
        kv = S[S_KV][3]
        qdd1 = W[W_QDD]
        c = hh / 6.0
        for j in range(6):
            e = max(e, c * abs(qd1[j] - kq[j]), c * w * abs(qdd1[j] - kv[j]))
    return e / tol


@njit_noalloc
def _first_step(fst, h_nom, adaptive):
    """The period's first step: the controller's carried proposal, else h_nom."""
    if fst.shape[0] < N_FST:
        raise ValueError("fst must hold N_FST values (t, root_y, next step)")
    return min(fst[FS_H], h_nom) if adaptive and fst[FS_H] > 0.0 else h_nom


@njit_noalloc
def _finite(q, qd):
    for j in range(6):
        if not (np.isfinite(q[j]) and np.isfinite(qd[j])):
            return False
    return True


@njit_noalloc
def _step_length(left, h_try, h_nom):
    """The error-controlled step [s] with ``left`` [s] to the period's end.

    No sliver before the end: the step stretches by up to 10 %, or what is left is halved
    when it is under two steps.
    """
    if left > 1.1 * h_try or left > h_nom * (1.0 + 1e-9):
        return 0.5 * left if left < 2.0 * h_try else h_try
    return left


@njit_noalloc
def _next_step(err, hh, h_try, h_nom, used):
    """(accepted, next step [s]) after a step of hh [s] with relative error estimate err.

    Rejected (err > 1, NaN included, unless hh is already H_MIN_S): retake shorter, by
    0.9 err^(-1/p) but at least 0.2. Accepted: the next step grows by at most 4, up to h_nom;
    a step cut short by the period's end only ever shrinks the proposal; never below H_MIN_S
    (a step accepted at H_MIN_S with a large estimate would otherwise propose ever shorter ones).
    """
    expo = 0.5 if used == 1 else 0.25
    if not err <= 1.0 and hh > H_MIN_S:
        r = 0.9 * err**-expo
        return False, max(hh * (r if r >= 0.2 else 0.2), H_MIN_S)
    fac = 4.0 if err <= 0.0 else min(4.0, 0.9 * err**-expo)
    if hh < h_try:
        return True, max(min(h_try, hh * fac) if fac < 1.0 else h_try, H_MIN_S)
    return True, max(min(h_nom, hh * fac), H_MIN_S)


@njit_alloc
def _reset_map(chs, scs, side, reset, q, qd, root_y, iopt):
    """The reset map of a model switch, in place on (q, qd): (heel behind, side, root_y).

    ``reset`` 1 (touchdown of the swing heel): if the swing heel is behind the stance toe the
    switch is refused (returns True: the run ends); else the impact. ``reset`` 2 (the swing
    foot lands flat): the impact, then the renumbering (paper eq. 25-29), which swaps ``side``
    and moves ``root_y`` to the new stance toe. Allocates, so it is kept out of the
    reference-count-free stepping loop (module jit), which calls it only at switches.
    """
    ch = chs[side]
    sc = scs[side]
    if reset == 1:
        heel_y = nb_keypoints(ch, sc, q, root_y)[7, 0]
        if heel_y < root_y:
            return True, side, root_y
        qd[:] = nb_impact(ch, sc, 1, q, qd, iopt[IO_IMPACT])
    elif reset == 2:
        qd[:] = nb_impact(ch, sc, 2, q, qd, iopt[IO_IMPACT])
        qn, qdn, root_y = nb_renumber(ch, chs[1 - side], sc, q, qd, root_y)
        q[:] = qn
        qd[:] = qdn
        side = 1 - side
    return False, side, root_y


@njit_noalloc
def nb_advance_w(chs, scs, q, qd, ist, fst, tau_table, dt, iopt, fopt, a, b, ev, forces, W, S):
    """Advance one simulator by one control period dt [s], in place.

    Args:
        chs, scs: (2, 6, 6), (2, 7) packed chains of both numberings.
        q, qd: (6,) state, updated in place. ist: int64 [mode, side, steps, ignored-mask];
        fst: float64 [t, root_y], both updated in place.
        tau_table: (4, 5) joint torques [N m] for models 1..4 (a row per model; the torque
            switches with the model).
        iopt, fopt, a, b: packed options and integrator tableau.
        ev: (MAX_EVENTS, 5) event buffer (t, code, from, to, terminal), filled from row 0.
        forces: (5,) output: contact forces at the final state.
        W, S: workspace and scratch (nb_make_work, nb_make_scratch).

    Returns:
        (status, number of events): status 0 running, 1 terminated, 2 non-finite.
    """
    mode = ist[ST_MODE]
    side = ist[ST_SIDE]
    steps = ist[ST_STEPS]
    ignored = ist[ST_IGNORED]
    t = fst[FS_T]
    root_y = fst[FS_ROOT]
    t_end = t + dt
    h_nom = dt / iopt[IO_SUBSTEPS]
    strict = iopt[IO_STRICT] != 0
    nev = 0
    status = 0
    switches = 0
    check = True
    tau6 = S[S_TAU6]
    g = S[S_G]
    g1 = S[S_G1]
    fo = S[S_F]
    k1 = S[S_K1]
    # first-same-as-last: the accelerations of the last evaluation at the current state are
    # the first stage of the next explicit step (not with the paper's finite-difference J-dot,
    # whose sample length changes with the step, nor for the implicit methods)
    explicit = iopt[IO_INTEGRATOR] != SEMI_IMPLICIT and iopt[IO_INTEGRATOR] != LIMEX
    reuse = iopt[IO_JDOT_FD] == 0 and explicit
    step_tol = fopt[FO_STEP_TOL]
    adaptive = iopt[IO_INTEGRATOR] == RK4_LIMEX_ADAPTIVE
    h_try = _first_step(fst, h_nom, adaptive)
    while True:
        ch = chs[side]
        sc = scs[side]
        for j in range(5):
            tau6[j + 1] = tau_table[mode - 1, j]
        k = -1
        if check:
            nb_evaluate_w(ch, sc, mode, q, qd, tau6, iopt, fopt, 0.0, W, fo, g)
            for j in range(6):
                k1[j] = W[W_QDD][j]
            k1[6] = fo[FC_SLIP]
            for kk in EVENT_PRIORITY:
                if _fired(g, kk, ignored):
                    k = kk
                    break
            if k < 0 and _fired(g, 0, ignored):
                k = 0
            check = False
        if k < 0:
            if t_end - t <= 1e-9 * dt:
                break
            hh = _step_length(t_end - t, h_try, h_nom) if adaptive else min(h_nom, t_end - t)
            used = nb_integrate_w(ch, sc, mode, q, qd, tau6, hh, iopt, fopt, a, b, W, S, reuse)
            q1 = S[S_Q1]
            qd1 = S[S_QD1]
            if not _finite(q1, qd1):
                if adaptive and hh > H_MIN_S:
                    h_try = max(0.2 * hh, H_MIN_S)
                    continue
                status = 2
                break
            fd = hh if iopt[IO_JDOT_FD] != 0 else 0.0
            nb_evaluate_w(ch, sc, mode, q1, qd1, tau6, iopt, fopt, fd, W, fo, g1)
            if adaptive:
                accepted, h_try = _next_step(
                    _step_error(S, W, hh, used, step_tol), hh, h_try, h_nom, used
                )
                if not accepted:
                    continue
            mask = 0
            for kk in range(N_GUARDS):
                if _fired(g1, kk, ignored):
                    mask |= 1 << kk
            if mask == 0:
                for j in range(6):
                    q[j] = q1[j]
                    qd[j] = qd1[j]
                    k1[j] = W[W_QDD][j]
                k1[6] = fo[FC_SLIP]
                for kk in range(N_GUARDS):
                    g[kk] = g1[kk]
                t += hh
                continue
            if iopt[IO_LOCATE] != 0:
                th = nb_locate_w(ch, sc, mode, q, qd, tau6, hh, mask, iopt, fopt, a, b, W, S, reuse)
                t += th * hh
                for j in range(6):
                    q[j] = S[S_QH][j]
                    qd[j] = S[S_QDH][j]
                nb_evaluate_w(ch, sc, mode, q, qd, tau6, iopt, fopt, fd, W, fo, g1)
            else:
                t += hh
                for j in range(6):
                    q[j] = q1[j]
                    qd[j] = qd1[j]
            for kk in EVENT_PRIORITY:
                if (mask >> kk) & 1 and g1[kk] <= 0.0:
                    k = kk
                    break
            if k < 0:
                if (mask & 1) and g1[0] <= 0.0:
                    k = 0
                else:
                    best = np.inf
                    for kk in range(N_GUARDS):
                        if (mask >> kk) & 1 and g1[kk] < best:
                            best = g1[kk]
                            k = kk
        # ---- handle event k at time t, state (q, qd)
        if k == 0:
            succ = SUCCESSOR[mode]
            behind, side, root_y = _reset_map(chs, scs, side, RESET[mode], q, qd, root_y, iopt)
            if behind:
                nev = _record(ev, nev, t, 9, mode, mode, 1)
                status = 1
                break
            nev = _record(ev, nev, t, 0, mode, succ, 0)
            if mode == 4:
                steps += 1
            mode = succ
            nb_project_w(chs[side], scs[side], mode, q, qd, W)
            ignored = 0
            switches += 1
            if adaptive:
                h_try = max(h_nom * EVENT_STEP_FRACTION, H_MIN_S)
            if switches > iopt[IO_MAX_SWITCHES]:
                nev = _record(ev, nev, t, 10, mode, mode, 1)
                status = 1
                break
            check = True
            if iopt[IO_STOP_AT_SWITCH] != 0:
                # hand control back at the switch: forces of the new model at the new state
                # with its torque row (its guards are checked when the next period starts)
                for j in range(5):
                    tau6[j + 1] = tau_table[mode - 1, j]
                nb_evaluate_w(chs[side], scs[side], mode, q, qd, tau6, iopt, fopt, 0.0, W, fo, g)
                break
        else:
            terminal = strict or FORCE_EVENT_FLAGS[k] == 0
            nev = _record(ev, nev, t, k, mode, mode, 1 if terminal else 0)
            if terminal:
                status = 1
                break
            ignored |= 1 << k
            check = True
    # the last evaluation (at an accepted step's end, at an event, or the check after a reset)
    # was made at the final state with the final model's torques: its forces are the output
    if status != 2:
        for j in range(N_FORCES):
            forces[j] = fo[j]
    ist[ST_MODE] = mode
    ist[ST_SIDE] = side
    ist[ST_STEPS] = steps
    ist[ST_IGNORED] = ignored
    fst[FS_T] = t
    fst[FS_ROOT] = root_y
    fst[FS_H] = h_try if adaptive else 0.0
    return status, nev


@njit(cache=True)
def nb_advance(chs, scs, q, qd, ist, fst, tau_table, dt, iopt, fopt, a, b, ev, forces):
    """:func:`nb_advance_w` with a fresh workspace (one simulator, one control period)."""
    return nb_advance_w(
        chs,
        scs,
        q,
        qd,
        ist,
        fst,
        tau_table,
        dt,
        iopt,
        fopt,
        a,
        b,
        ev,
        forces,
        nb_make_work(),
        nb_make_scratch(),
    )


@njit(cache=True)
def _advance_range(
    chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, lo, hi
):
    """:func:`nb_advance_w` over rows lo..hi-1 with one workspace; rows with STATUS != 0 skip."""
    _advance_rows(
        chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, lo, hi,
        nb_make_work(), nb_make_scratch(),
    )  # fmt: skip


@njit_noalloc
def _advance_rows(
    chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, lo, hi, W, S
):
    """The rows' loop of :func:`_advance_range`, given its workspace and scratch."""
    for i in range(lo, hi):
        if STATUS[i] != 0:
            NEV[i] = 0
            continue
        STATUS[i], NEV[i] = nb_advance_w(
            chs,
            scs,
            Q[i],
            QD[i],
            IST[i],
            FST[i],
            TAU[i],
            dt,
            iopt,
            fopt,
            a,
            b,
            EV[i],
            FORCES[i],
            W,
            S,
        )


@njit(cache=True)
def nb_advance_batch(chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV):
    """:func:`nb_advance_w` over N simulators (rows of every array); skips rows with STATUS != 0."""
    _advance_range(
        chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, 0, Q.shape[0]
    )


@njit(cache=True, parallel=True)
def nb_advance_batch_parallel(
    chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, nt
):
    """:func:`nb_advance_batch` split into ``nt`` chunks, one per thread (same results)."""
    n = Q.shape[0]
    chunk = (n + nt - 1) // nt
    for c in numba.prange(nt):
        _advance_range(
            chs,
            scs,
            Q,
            QD,
            IST,
            FST,
            TAU,
            dt,
            iopt,
            fopt,
            a,
            b,
            EV,
            FORCES,
            STATUS,
            NEV,
            c * chunk,
            min(n, (c + 1) * chunk),
        )


PARALLEL_MIN_BATCH = 8
"""Batches at least this large are stepped by the multi-threaded kernel."""


# --------------------------------------------------------------------------- public API


def _tau_table(tau) -> np.ndarray:
    a = np.asarray(tau, dtype=np.float64)
    if a.shape == (N_ACTUATED,):
        a = np.broadcast_to(a, (4, N_ACTUATED))
    elif a.shape != (4, N_ACTUATED):
        raise ValueError(f"tau must have shape (5,) or (4, 5), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"tau must be finite, got {a}")
    return np.ascontiguousarray(a)


def events_from_buffer(ev: np.ndarray, nev: int) -> tuple[Event, ...]:
    """Decode the first ``nev`` rows of an event buffer."""
    return tuple(
        Event(float(r[0]), EventCode(int(r[1])), int(r[2]), int(r[3]), bool(r[4])) for r in ev[:nev]
    )


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
    fst = np.array([state.t, state.root_y, state.next_step_s])
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
        self.fst[i] = (state.t, state.root_y, state.next_step_s)
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


@njit(cache=True)
def nb_start_batch(chs, scs, Q, QD, IST, FST, FORCES, STATUS, NEV, idx, modes, iopt, fopt):
    """Start slots ``idx`` (their Q, QD set) in ``modes``; returns each one's lowest point z [m].

    Leg A stands with its toe at y = 0 and t = 0, no step completed. Computes the contact
    forces at zero torque (for the first observation) and clears the status and event count.
    The caller rejects states whose lowest point is below ground.
    """
    W = nb_make_work()
    g = np.empty(N_GUARDS)
    tau6 = np.zeros(6)
    low = np.empty(idx.shape[0])
    for k in range(idx.shape[0]):
        i = idx[k]
        IST[i, :] = 0
        IST[i, ST_MODE] = modes[k]
        FST[i, :] = 0.0
        side = IST[i, ST_SIDE]
        pts = nb_keypoints(chs[side], scs[side], Q[i], FST[i, FS_ROOT])
        low[k] = pts[:, 1].min()
        nb_evaluate_w(
            chs[side],
            scs[side],
            IST[i, ST_MODE],
            Q[i],
            QD[i],
            tau6,
            iopt,
            fopt,
            0.0,
            W,
            FORCES[i],
            g,
        )
        STATUS[i] = STATUS_OK
        NEV[i] = 0
    return low


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
