"""Time integrators as data: one signature, consumed by the compiled stepping loop.

Each integrator is an explicit Runge-Kutta tableau ``(A, b)`` applied to the second-order
system ``d/dt (q, qd) = (qd, qdd(q, qd))``, except the semi-implicit Euler, whose velocity
update treats the joint damping implicitly: it solves ``(M + h D) qdd = tau - b - D qd + ...``
then ``qd' = qd + h qdd`` and ``q' = q + h qd'`` (the implicit-damping Euler of MJX), and
LIMEX, built for the stiff contacts: the same linearly implicit Euler step with the point
contact's friction direction also taken at the step's end (the regularised friction's slope
near zero slip, K f_n / eps, is what makes contact scenes stiff; the solve stays exact in f_n,
see :func:`~biped_constraint_env.hybrid.nb_solve_mode_w`), made second order by one Richardson
extrapolation, ``y1 = 2 Phi_{h/2}(Phi_{h/2}(y0)) - Phi_h(y0)`` (the first member of
Deuflhard's linearly implicit extrapolation family, LIMEX). Its amplification factor for
``y' = z y / h`` is ``2 / (1 - z/2)^2 - 1 / (1 - z)``, which goes to 0 as z -> -inf: L-stable.

RK4_LIMEX switches between the two by stiffness, step by step: the friction is stiff only
while a point contact slips slowly (its rate K f_n / eps at zero slip falls as (1 - s^2)^(3/2)
with the regularised slip sign s), and the joint damping is within RK4's stability at the
steps used. A step whose start or stage states show a slow slip, or a slip reversal, is taken
by LIMEX instead (:func:`friction_is_stiff`); every other step is RK4, fourth order. The choice
is made from the step's own states, so it is deterministic and the same in batched and single
runs.

RK4_LIMEX_ADAPTIVE takes the same steps, of a length chosen by error control (in
:func:`~biped_constraint_env.simulator.nb_advance_w`): each step's error is estimated for free
(an RK4 step: h/6 (f(y1) - k4), the gap to the third-order solution that uses the end state's
evaluation, which the guards need anyway; a LIMEX step: the gap between its two members), a
step whose estimate exceeds ``step_tol`` is retaken shorter, and the next step is
``h min(4, 0.9 (tol / err)^(1/p))`` (p = 4 after RK4, 2 after LIMEX), never longer than the
substep. So the steps are long (10 ms) in smooth motion and short only in the fast transients
an impact starts; events are located on the accepted step's Hermite interpolant (dense
output, one evaluation per iteration) instead of by retaking the step. The controller's next
step is part of the state (``SimState.next_step_s``), so results are reproducible from a state.

``STABILITY_CONSTANT`` is the real-axis stability limit ``h lambda`` of each method for the
linear damping mode ``qdd = -lambda qd``: 2 for explicit Euler and RK2, about 2.785 for RK4,
unbounded for the semi-implicit method and LIMEX (their damping update is unconditionally
stable).
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from .jit import njit_noalloc


class Integrator(IntEnum):
    """Integration method per substep (values are the compiled core's codes)."""

    EULER = 0
    """Explicit Euler, first order (the paper's)."""
    SEMI_IMPLICIT = 1
    """Semi-implicit Euler with implicit joint damping, first order (default family)."""
    RK2 = 2
    """Explicit midpoint, second order."""
    RK4 = 3
    """Classical Runge-Kutta, fourth order."""
    LIMEX = 4
    """Linearly implicit Euler (joint damping and contact friction implicit) with one
    Richardson extrapolation: second order, L-stable, with an error estimate (see module)."""
    RK4_LIMEX = 5
    """Stiffness switching: RK4, except that a step whose point contact slips through the
    friction's stiff band near zero slip is taken by LIMEX (see :func:`friction_is_stiff`)."""
    RK4_LIMEX_ADAPTIVE = 6
    """RK4_LIMEX with error-controlled steps (the default): each step's error is estimated
    at no extra evaluation and the step length chosen from it, up to the substep length."""


_RK4_TABLEAU = (
    [[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
    [1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0],
)
_RK4_STABILITY = 2.785293563405282

_TABLEAUS: dict[Integrator, tuple[list[list[float]], list[float]]] = {
    Integrator.EULER: ([[0.0]], [1.0]),
    Integrator.SEMI_IMPLICIT: ([[0.0]], [1.0]),  # unused: handled by its own update rule
    Integrator.LIMEX: ([[0.0]], [1.0]),  # unused: handled by its own update rule
    Integrator.RK4_LIMEX: _RK4_TABLEAU,  # used on the non-stiff steps
    Integrator.RK4_LIMEX_ADAPTIVE: _RK4_TABLEAU,  # used on the non-stiff steps
    Integrator.RK2: ([[0.0, 0.0], [0.5, 0.0]], [0.0, 1.0]),
    Integrator.RK4: _RK4_TABLEAU,
}

MAX_STAGES = 4
"""Largest number of stages of any tableau here."""

ORDER: dict[Integrator, int] = {
    Integrator.EULER: 1,
    Integrator.SEMI_IMPLICIT: 1,
    Integrator.RK2: 2,
    Integrator.RK4: 4,
    Integrator.LIMEX: 2,
    Integrator.RK4_LIMEX: 4,
    Integrator.RK4_LIMEX_ADAPTIVE: 4,
}
"""Global order of accuracy of each method (at fixed steps)."""

STABILITY_CONSTANT: dict[Integrator, float] = {
    Integrator.EULER: 2.0,
    Integrator.SEMI_IMPLICIT: float("inf"),
    Integrator.RK2: 2.0,
    Integrator.RK4: _RK4_STABILITY,
    Integrator.LIMEX: float("inf"),
    Integrator.RK4_LIMEX: _RK4_STABILITY,
    Integrator.RK4_LIMEX_ADAPTIVE: _RK4_STABILITY,
}
"""Largest stable h * lambda on the negative real axis (lambda: eigenvalue of M^-1 D)."""

EVALS_PER_STEP: dict[Integrator, int] = {
    Integrator.EULER: 1,
    Integrator.SEMI_IMPLICIT: 1,
    Integrator.RK2: 2,
    Integrator.RK4: 4,
    Integrator.LIMEX: 3,
    Integrator.RK4_LIMEX: 4,
    Integrator.RK4_LIMEX_ADAPTIVE: 4,
}
"""Constrained dynamics evaluations per integration step."""


FRICTION_RATE_BOUND = 1.0e5
"""Bound [1/s] on the point contact's friction rate at zero slip, K f_n / eps times the
tangential inverse mass of the constrained chain (6.5e4 measured at the full-cycle scene's
slip reversal, benchmarks.accuracy). Away from zero slip the rate falls as (1 - s^2)^(3/2),
s being the regularised slip sign."""

SWITCH_H_LAMBDA = 0.5
"""RK4_LIMEX takes a step by LIMEX when h * FRICTION_RATE_BOUND * (1 - s^2)^(3/2) exceeds this
at any of RK4's stage states (or when the slip changes sign among them): a fifth of RK4's
stability limit, so that the explicit steps are also accurate in the friction's fast mode."""


@njit_noalloc
def friction_is_stiff(slip_sign: float, h: float) -> bool:
    """Whether RK4_LIMEX treats a step of h [s] at regularised slip sign s as stiff.

    Compiled: the stepping loop calls it at every stage state of a point-contact step.
    """
    u = 1.0 - slip_sign * slip_sign
    return h * FRICTION_RATE_BOUND * u * np.sqrt(u) > SWITCH_H_LAMBDA


def tableau(method: Integrator) -> tuple[np.ndarray, np.ndarray]:
    """(A (4, 4), b (4,)) zero-padded explicit Runge-Kutta tableau of ``method``."""
    a_rows, b_row = _TABLEAUS[Integrator(method)]
    a = np.zeros((MAX_STAGES, MAX_STAGES))
    b = np.zeros(MAX_STAGES)
    a[: len(a_rows), : len(a_rows)] = a_rows
    b[: len(b_row)] = b_row
    return a, b


def parse_integrator(value: str | int | Integrator) -> Integrator:
    """Integrator from its name or integer code.

    Names: ``"euler"``, ``"semi_implicit"``, ``"rk2"``, ``"rk4"``, ``"limex"``, ``"rk4_limex"``,
    ``"rk4_limex_adaptive"``.
    """
    if isinstance(value, str):
        try:
            return Integrator[value.upper()]
        except KeyError:
            names = [m.name.lower() for m in Integrator]
            raise ValueError(f"integrator must be one of {names}, got {value!r}") from None
    try:
        return Integrator(value)
    except ValueError:
        raise ValueError(f"unknown integrator code {value!r}") from None
