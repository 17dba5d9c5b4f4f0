import doctest

import gymnasium as gym

import biped_constraint_env
from biped_constraint_env import env as env_module


def test_registered_with_string_entry_points():
    spec = gym.spec("ConstrainedBiped-v0")
    assert spec.entry_point == "biped_constraint_env.env:ConstrainedBipedEnv"
    assert spec.vector_entry_point == "biped_constraint_env.vector_env:ConstrainedBipedVectorEnv"
    assert spec.max_episode_steps == biped_constraint_env.MAX_EPISODE_STEPS == 1000


def test_env_docstring_example_runs():
    result = doctest.testmod(env_module, verbose=False)
    assert result.attempted >= 1 and result.failed == 0
