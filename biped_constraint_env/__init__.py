"""biped-constraint-env: a planar six-link biped whose ground contact is a constraint.

The four-model Newton-Euler simulator of Maeba, Minami, Wang and Yanou (2013), compiled with
numba, and the Gymnasium environment ``ConstrainedBiped-v0`` (registered on import).
"""

from __future__ import annotations

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

for _id, _kwargs in (("ConstrainedBiped-v0", {"preset": "fast"}), (ENV_ID, {})):
    if _id not in gymnasium.registry:
        gymnasium.register(
            id=_id,
            entry_point="biped_constraint_env.env:ConstrainedBipedEnv",
            vector_entry_point="biped_constraint_env.vector_env:ConstrainedBipedVectorEnv",
            max_episode_steps=MAX_EPISODE_STEPS,
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
