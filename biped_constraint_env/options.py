"""The simulator's options (SimOptions) and its fidelity presets, validated by name."""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from .hybrid import (
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
    N_IOPT,
)
from .integrators import (
    parse_integrator,
    tableau,
)
from .validation import check_bool, check_choice, check_int, check_real

STEP_TOL_MIN = 1e-10
"""Smallest accepted ``step_tol`` (below it every step would be H_MIN_S anyway)."""


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
    """Numerical and modelling options of the simulator (see docs/conventions.md).

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
(docs/speed_accuracy.md), at about 700 evaluations per simulated second."""

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
