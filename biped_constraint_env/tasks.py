"""Tasks and fidelity presets, as data: the env's defaults and the paper's setting.

A *task* fixes the control period, the start distribution, whether a period ends at a model
switch, the fidelity preset and the learning task's parts (reward, action, observation,
command); each is written as the env's own keyword argument of that part, and one given
explicitly overrides the task's (the ``physics`` and ``start`` dicts key by key; ``action`` and
``reward`` dicts of the task's kind key by key).
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

TASK_DEFAULTS: dict[str, Any] = {
    "reward": "env",
    "action": "torque",
    "observation": (),
    "command": None,
}
"""The learning-task settings every task starts from (the env's own reward, torques)."""

TRACK_PD_OFFSET_RAD = (0.2, 0.0, 0.0, 0.0, 0.0)
"""``task="track"``'s stance-ankle offset [rad]: the smallest on a 0.05 rad grid with which a
zero network output passes the mid-stride start's first period
(docs/recipes/ppo_from_scratch.md)."""

TASKS: dict[str, dict[str, Any]] = {
    "walk": {
        "preset": "default",
        "dt": 0.005,
        "physics": {"stop_at_switch": True},
        "start": "midstride",
    },  # fmt: skip
    "track": {
        "preset": "default",
        "dt": 0.005,
        "physics": {"stop_at_switch": True},
        "start": {"reference": 0.5, "midstride": 0.5},
        "reward": "tracking",
        "action": {"kind": "pd", "around": "reference", "offset": TRACK_PD_OFFSET_RAD},
        "observation": ("phase",),
    },
    "command": {
        "preset": "default",
        "dt": 0.02,
        "physics": {"stop_at_switch": True},
        "start": "rest",
        "reward": {"kind": "command", "gated": True},
        "observation": ("phase",),
        "command": {"range": (0.0, 2.0), "zero_fraction": 0.1, "resample_s": (1.0, 5.0)},
    },
    "paper": {
        "preset": "paper",
        "dt": PAPER_SAMPLE_TIME_S,
        "physics": {"stop_at_switch": False},
        "start": "rest",
    },
}
"""``task="walk"`` (default): accurate physics, 5 ms control, a period ends at each model switch
(the torque changes there, as in the paper), mid-stride start. ``task="track"``: the walking
task set up for learning from the recorded reference walk (the from-scratch recipe's task:
tracking reward, half the starts at reference states, PD targets about the reference pose with
the stance-ankle offset, the contact clock observed); every one of these settings can still
be given. ``task="command"``: a commanded forward speed (:mod:`.command`: 0-2 m/s, 10% zero,
resampled every 1-5 s, observed), the command reward (no recorded motion), 20 ms torques, the
contact clock observed, the start at rest. ``task="paper"``: the paper's setting (its
numerics, 20 ms, torques held through switches, start at rest in model 1)."""

EPISODE_S = 30.0
"""An episode's time limit by default [s] of simulated time (``time_limit_s``): at any control
period, whether its periods end early at model switches or not."""
MAX_EPISODE_S = 1e5
"""Longest ``time_limit_s`` accepted [s]."""
MAX_EPISODE_STEPS = 6000
"""A limit in control periods that the training recipes keep for their selection episodes and
training env (6000 periods: 28-30 s at the walking task's 5 ms, 120 s at 20 ms)."""


MAX_DT_S = 1.0
"""Longest control period accepted [s] (the paper's is 20 ms)."""
MIN_DT_S = 2e-3
"""Shortest control period accepted [s]: 15,000 periods in a 30 s episode (about 4 s of one
core with a Python controller in the loop; the paper's Table 2 runs at 2 ms)."""
MIN_STEP_S = 5e-5
"""Shortest fixed integration step an env accepts [s] (``dt / substeps``): 600,000 steps in
30 s. The simulator itself accepts finer steps (the accuracy study's references)."""
MIN_STEP_TOL = 1e-8
"""Smallest ``step_tol`` an env accepts (error-controlled steps of about 1 ms at the default
walk; the simulator accepts down to 1e-10 for references)."""
MIN_EVENT_TOL = 1e-12
"""Smallest ``pos_tol_m`` [m] and ``time_tol_s`` [s] an env accepts."""


def resolve_task(task: str, **overrides: Any) -> dict[str, Any]:
    """The task's settings with the explicitly given ones (not None) on top.

    Whole parts replace the task's; the parts that merge key by key onto the task's (physics,
    start, action, reward) are merged by :func:`~.settings.make_settings`.
    """
    check_choice("task", task, sorted(TASKS))
    given = {k: v for k, v in overrides.items() if v is not None}
    return {**TASK_DEFAULTS, **TASKS[task], **given}


def resolve_options(preset: str, dt: float, overrides: dict[str, Any]) -> SimOptions:
    """The simulator options of a preset with per-option overrides (None = keep).

    A preset's ``substeps`` are per the paper's 20 ms period: for another control period dt
    they are scaled so that the substep is never longer than the preset's (x 8 per 20 ms is
    x 2 per 5 ms, 2.5 ms substeps; the default's x 1 per 20 ms is x 1 per 5 ms). An explicit
    ``substeps`` is per period, as given.

    Every setting that scales the work is bounded here, so that a 30 s episode costs seconds,
    not days: ``dt`` in [:data:`MIN_DT_S`, :data:`MAX_DT_S`], integration steps no shorter
    than :data:`MIN_STEP_S`, ``step_tol`` >= :data:`MIN_STEP_TOL`, event tolerances >=
    :data:`MIN_EVENT_TOL`.
    """
    check_choice("preset", preset, sorted(PRESETS))
    dt = check_real("dt", dt, MIN_DT_S, MAX_DT_S, unit=" [s]")
    base = PRESETS[preset]
    changes = {k: v for k, v in overrides.items() if v is not None}
    if "substeps" not in changes:
        changes["substeps"] = max(1, math.ceil(base.substeps * dt / PAPER_SAMPLE_TIME_S - 1e-9))
    opts = base.replace(**changes)
    most = max(1, int(dt / MIN_STEP_S + 1e-9))
    if opts.substeps > most:
        raise ValueError(f"substeps must be at most {most} at dt = {dt} s (steps of at least "
                         f"{MIN_STEP_S * 1e6:g} us), got {opts.substeps}")  # fmt: skip
    if opts.step_tol < MIN_STEP_TOL:
        raise ValueError(f"step_tol must be at least {MIN_STEP_TOL:g}, got {opts.step_tol!r}")
    for name in ("pos_tol_m", "time_tol_s"):
        if getattr(opts, name) < MIN_EVENT_TOL:
            raise ValueError(f"{name} must be at least {MIN_EVENT_TOL:g}, got "
                             f"{getattr(opts, name)!r}")  # fmt: skip
    return opts
