"""biped-constraint-env: a planar six-link biped whose ground contact is a constraint.

The four-model Newton-Euler simulator of Maeba, Minami, Wang and Yanou (2013), compiled with
numba, and the Gymnasium environment ``ConstrainedBiped-v0`` (registered on import).
"""

from __future__ import annotations

import warnings

import gymnasium

from .model import BipedParams, ChainModel, LinkParams, chain_for, paper_biped
from .modes import MODE_TABLE, EventCode, Mode
from .simulator import (
    DEFAULT_OPTIONS,
    FAST_OPTIONS,
    PAPER_OPTIONS,
    Event,
    SimOptions,
    SimState,
    SimulationError,
    StepResult,
    rollout,
    step,
)

__version__ = "0.1.0"

ENV_ID = "ConstrainedBiped-v1"
"""The current version: the accuracy study's default integrator (RK4 x 16 per 20 ms)."""
MAX_EPISODE_STEPS = 1000
"""Time limit in control periods (1000 x 20 ms = 20 s)."""

WALK_ENV_ID = "ConstrainedBiped-v2"
"""The walking task: event-driven 5 ms control from a mid-stride start, 30 s episodes."""
WALK_MAX_EPISODE_STEPS = 6000
"""v2's time limit in control periods (6000 x 5 ms = 30 s, room for ~35 steps)."""
WALK_KWARGS = {"dt": 0.005, "stop_at_switch": True, "start": "midstride"}
"""v2's arguments on top of v1's defaults."""

# v0 and v1 stay the paper-reproduction tasks (20 ms, start at rest) next to the walking task
# v2; Gymnasium's "out of date" warning would wrongly tell their users to move to v2.
warnings.filterwarnings(
    "ignore", message=r".*ConstrainedBiped-v[01] is out of date", category=DeprecationWarning
)
for _id, _kwargs, _limit in (
    ("ConstrainedBiped-v0", {"preset": "fast"}, MAX_EPISODE_STEPS),
    (ENV_ID, {}, MAX_EPISODE_STEPS),
    (WALK_ENV_ID, WALK_KWARGS, WALK_MAX_EPISODE_STEPS),
):
    if _id not in gymnasium.registry:
        gymnasium.register(
            id=_id,
            entry_point="biped_constraint_env.env:ConstrainedBipedEnv",
            vector_entry_point="biped_constraint_env.vector_env:ConstrainedBipedVectorEnv",
            max_episode_steps=_limit,
            kwargs=_kwargs,
        )

__all__ = [
    "BipedParams",
    "ChainModel",
    "DEFAULT_OPTIONS",
    "ENV_ID",
    "Event",
    "FAST_OPTIONS",
    "EventCode",
    "LinkParams",
    "MODE_TABLE",
    "Mode",
    "PAPER_OPTIONS",
    "SimOptions",
    "SimState",
    "SimulationError",
    "StepResult",
    "chain_for",
    "paper_biped",
    "rollout",
    "step",
]
