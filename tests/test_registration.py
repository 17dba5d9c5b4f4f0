import doctest

import gymnasium as gym
import pytest

import biped_constraint_env
from biped_constraint_env import env as env_module


def test_registered_with_string_entry_points():
    for env_id in ("ConstrainedBiped-v0", "ConstrainedBiped-v1"):
        spec = gym.spec(env_id)
        assert spec.kwargs == ({"preset": "fast"} if env_id.endswith("v0") else {})
        assert spec.entry_point == "biped_constraint_env.env:ConstrainedBipedEnv"
        assert (
            spec.vector_entry_point == "biped_constraint_env.vector_env:ConstrainedBipedVectorEnv"
        )
        assert spec.max_episode_steps == biped_constraint_env.MAX_EPISODE_STEPS == 1000


def test_versions_differ_only_in_the_integrator():
    with pytest.warns(DeprecationWarning, match="out of date"):
        v0 = gym.make("ConstrainedBiped-v0").unwrapped.options
    v1 = gym.make("ConstrainedBiped-v1").unwrapped.options
    assert (v0.integrator, v0.substeps) == ("rk2", 4) and (v1.integrator, v1.substeps) == (
        "rk4",
        16,
    )
    assert v0.replace(integrator="rk4", substeps=16) == v1
    with pytest.warns(DeprecationWarning, match="out of date"):
        vec = gym.make_vec(
            "ConstrainedBiped-v0", num_envs=2, vectorization_mode="vector_entry_point"
        )
    assert vec.options == v0


def test_env_docstring_example_runs():
    result = doctest.testmod(env_module, verbose=False)
    assert result.attempted >= 1 and result.failed == 0
