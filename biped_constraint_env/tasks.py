"""Tasks and fidelity presets, as data: the env's defaults and the paper's setting.

A *task* fixes the control period, the start distribution, whether a period ends at a model
switch, and the fidelity preset; every one of these stays a keyword argument of the env that
overrides the task's value.
"""

from __future__ import annotations

import math
from typing import Any

from .simulator import (
    DEFAULT_OPTIONS,
    FAST_OPTIONS,
    FIXED_STEP_OPTIONS,
    PAPER_OPTIONS,
    SimOptions,
)
from .units import PAPER_SAMPLE_TIME_S
from .validation import check_choice, check_real

PRESETS: dict[str, SimOptions] = {
    "default": DEFAULT_OPTIONS,
    "fixed_step": FIXED_STEP_OPTIONS,
    "fast": FAST_OPTIONS,
    "paper": PAPER_OPTIONS,
}
"""Fidelity presets: the accurate defaults (error-controlled RK4_LIMEX, steps up to the
period), the accurate fixed-step "fixed_step" (RK4_LIMEX x 8 per 20 ms), the cheaper "fast"
(RK2 x 4; fails the accuracy rule over a walking cycle) and the paper's own numerical choices."""

TASKS: dict[str, dict[str, Any]] = {
    "walk": {"preset": "default", "dt": 0.005, "stop_at_switch": True, "start": "midstride"},
    "paper": {
        "preset": "paper",
        "dt": PAPER_SAMPLE_TIME_S,
        "stop_at_switch": False,
        "start": "rest",
    },
}
"""``task="walk"`` (default): accurate physics, 5 ms control, a period ends at each model switch
(the torque changes there, as in the paper), mid-stride start. ``task="paper"``: the paper's
setting (its numerics, 20 ms, torques held through switches, start at rest in model 1)."""

MAX_EPISODE_STEPS = 6000
"""Time limit in control periods at registration (6000 x 5 ms = 30 s of the walking task)."""


MAX_DT_S = 1.0
"""Longest control period accepted [s] (the paper's is 20 ms)."""


def resolve_task(task: str, **overrides: Any) -> dict[str, Any]:
    """The task's settings with the explicitly given ones (not None) on top."""
    check_choice("task", task, sorted(TASKS))
    return {**TASKS[task], **{k: v for k, v in overrides.items() if v is not None}}


def resolve_options(preset: str, dt: float, overrides: dict[str, Any]) -> SimOptions:
    """The simulator options of a preset with per-option overrides (None = keep).

    A preset's ``substeps`` are per the paper's 20 ms period: for another control period dt
    they are scaled so that the substep is never longer than the preset's (x 8 per 20 ms is
    x 2 per 5 ms, 2.5 ms substeps; the default's x 1 per 20 ms is x 1 per 5 ms). An explicit
    ``substeps`` is per period, as given.
    """
    check_choice("preset", preset, sorted(PRESETS))
    dt = check_real("dt", dt, 0.0, MAX_DT_S, low_open=True, unit=" [s]")
    base = PRESETS[preset]
    changes = {k: v for k, v in overrides.items() if v is not None}
    if "substeps" not in changes:
        changes["substeps"] = max(1, math.ceil(base.substeps * dt / PAPER_SAMPLE_TIME_S - 1e-9))
    return base.replace(**changes)
