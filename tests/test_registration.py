import doctest

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env
from biped_constraint_env import env as env_module
from biped_constraint_env.tasks import TASKS


def test_one_id_with_string_entry_points():
    ids = [k for k in gym.registry if "ConstrainedBiped" in k]
    assert ids == ["ConstrainedBiped-v0"]
    spec = gym.spec("ConstrainedBiped-v0")
    assert spec.kwargs == {}
    assert spec.entry_point == "biped_constraint_env.env:ConstrainedBipedEnv"
    assert spec.vector_entry_point == "biped_constraint_env.vector_env:ConstrainedBipedVectorEnv"
    assert spec.max_episode_steps is None  # episodes end by simulated time (time_limit_s, 30 s)
    assert biped_constraint_env.MAX_EPISODE_STEPS == 6000  # the recipes' selection episodes


def test_defaults_are_the_accurate_physics_and_the_walking_task():
    env = gym.make("ConstrainedBiped-v0").unwrapped
    assert env.options == biped_constraint_env.DEFAULT_OPTIONS.replace(stop_at_switch=True)
    assert (env.dt, env.settings.start.start, env.task) == (0.005, "midstride", "walk")
    _, info = env.reset(seed=0)
    assert info["mode"] == 2


def test_paper_task_and_overrides():
    env = gym.make("ConstrainedBiped-v0", task="paper").unwrapped
    assert env.options == biped_constraint_env.PAPER_OPTIONS
    assert (env.dt, env.settings.start.start) == (0.02, "rest")
    _, info = env.reset(seed=0)
    assert info["mode"] == 1
    # an explicit argument overrides the task's value, the rest of the task stays
    env = gym.make("ConstrainedBiped-v0", task="paper", preset="default").unwrapped
    assert env.options == biped_constraint_env.DEFAULT_OPTIONS and env.dt == 0.02
    env = gym.make("ConstrainedBiped-v0", preset="fast").unwrapped
    assert (env.options.integrator, env.options.substeps, env.dt) == ("rk2", 1, 0.005)
    # a preset keeps its substep length at any control period; explicit substeps are per period
    assert gym.make("ConstrainedBiped-v0").unwrapped.options.substeps == 1  # steps <= 5 ms
    fixed = dict(preset="fixed_step")
    assert gym.make("ConstrainedBiped-v0", **fixed).unwrapped.options.substeps == 2  # 2.5 ms
    assert gym.make("ConstrainedBiped-v0", dt=0.007, **fixed).unwrapped.options.substeps == 3
    assert gym.make("ConstrainedBiped-v0", physics={"substeps": 5}).unwrapped.options.substeps == 5
    assert set(TASKS) == {"walk", "track", "command", "paper"}


def test_vector_env_takes_the_same_task():
    vec = gym.make_vec(
        "ConstrainedBiped-v0", num_envs=2, vectorization_mode="vector_entry_point", task="paper"
    )
    single = gym.make("ConstrainedBiped-v0", task="paper").unwrapped
    assert vec.options == single.options and vec.dt == single.dt
    obs, _ = vec.reset(seed=3)
    o0, _ = single.reset(seed=3)
    np.testing.assert_array_equal(obs[0], o0)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"task": "run"}, "task"),
        ({"preset": "turbo"}, "preset"),
        ({"dt": 0.0}, "dt"),
        ({"start": "flying"}, "start"),
    ],
)
def test_bad_task_arguments_name_themselves(kwargs, name):
    with pytest.raises(ValueError, match=name):
        gym.make("ConstrainedBiped-v0", **kwargs)


def test_env_docstring_example_runs():
    result = doctest.testmod(env_module, verbose=False)
    assert result.attempted >= 1 and result.failed == 0
