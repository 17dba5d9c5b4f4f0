"""biped-constraint-env: a planar six-link biped whose ground contact is a constraint.

The four-model Newton-Euler simulator of Maeba, Minami, Wang and Yanou (2013), compiled with
numba, and the Gymnasium environment ``ConstrainedBiped-v0`` (registered on import).
"""

from __future__ import annotations

import gymnasium

from . import _first_use  # noqa: F401  (says so before a first compile)
from .model import BipedParams, ChainModel, LinkParams, chain_for, paper_biped
from .modes import MODE_TABLE, EventCode, Mode
from .simulator import (
    DEFAULT_OPTIONS,
    FAST_OPTIONS,
    FIXED_STEP_OPTIONS,
    PAPER_OPTIONS,
    Event,
    SimOptions,
    SimState,
    SimulationError,
    StepResult,
    rollout,
    step,
)
from .tasks import MAX_EPISODE_STEPS, PRESETS, TASKS

__version__ = "0.1.0"

ENV_ID = "ConstrainedBiped-v0"
"""The environment's one id: accurate physics and the walking task by default; the paper's
setting with ``gym.make(ENV_ID, task="paper")``."""

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="biped_constraint_env.env:ConstrainedBipedEnv",
        vector_entry_point="biped_constraint_env.vector_env:ConstrainedBipedVectorEnv",
    )  # episodes end by simulated time (the env's ``time_limit_s``), not by period count

__all__ = [
    "BipedParams",
    "ChainModel",
    "DEFAULT_OPTIONS",
    "ENV_ID",
    "Event",
    "FAST_OPTIONS",
    "FIXED_STEP_OPTIONS",
    "EventCode",
    "LinkParams",
    "MAX_EPISODE_STEPS",
    "MODE_TABLE",
    "Mode",
    "PAPER_OPTIONS",
    "PRESETS",
    "SimOptions",
    "SimState",
    "SimulationError",
    "StepResult",
    "TASKS",
    "chain_for",
    "paper_biped",
    "rollout",
    "step",
]
