"""Property-based fuzzing of the env's inputs: make kwargs, reset options and actions.

Whatever is given, the env either refuses it with a ``ValueError``/``TypeError`` that names
the offending argument, or runs and returns finite observations inside the observation space.
A hang fails the run: a watchdog dumps the stacks and exits after ``HANG_S`` seconds.
"""

import faulthandler
import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import biped_constraint_env  # noqa: F401
from biped_constraint_env.env import ENV_ARGUMENTS, ConstrainedBipedEnv
from biped_constraint_env.starts import RESET_OPTION_KEYS

HANG_S = 600
"""Seconds one fuzz test may take before the watchdog ends the process (a hang, not a slow
example: every example is a make, a reset and a step)."""
FUZZ = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,  # the same examples on every run: a failure reproduces
    suppress_health_check=[HealthCheck.too_slow],
)

numbers = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-2.0, max_value=2.0),
    st.floats(min_value=1e-12, max_value=0.05),
)
anything = st.one_of(
    st.none(),
    numbers,
    st.text(max_size=6),
    st.sampled_from(
        [
            "walk",
            "paper",
            "rest",
            "midstride",
            "default",
            "fast",
            "clip",
            "raise",
            "tracking",
            "pd",
            "fixed",
            "reference",
        ]
    ),
    st.lists(numbers, max_size=7),
    st.dictionaries(st.text(max_size=3), numbers, max_size=2),
)
MAKE_ARGUMENTS = [a for a in ENV_ARGUMENTS if a != "render_mode"]  # "human" opens a window


@pytest.fixture(autouse=True)
def watchdog():
    faulthandler.dump_traceback_later(HANG_S, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


def _names_one_of(err: Exception, names) -> bool:
    msg = str(err)
    return any(str(n) in msg or repr(n) in msg for n in names)


def _check_finite(env, obs) -> None:
    assert np.all(np.isfinite(obs)), obs
    assert env.observation_space.contains(obs), obs


@FUZZ
@given(
    kwargs=st.dictionaries(
        st.one_of(st.sampled_from(MAKE_ARGUMENTS), st.text(min_size=1, max_size=8)),
        anything,
        max_size=4,
    )
)
def test_make_kwargs_are_refused_by_name_or_run(kwargs):
    try:
        env = ConstrainedBipedEnv(**kwargs)
        obs, _ = env.reset(seed=0)
        _check_finite(env, obs)
        obs, reward, *_ = env.step(np.zeros(5))
    except (ValueError, TypeError) as e:
        assert _names_one_of(e, kwargs), f"{type(e).__name__}: {e} (kwargs {kwargs})"
        return
    _check_finite(env, obs)
    assert math.isfinite(reward)


@FUZZ
@given(
    options=st.one_of(
        anything,
        st.dictionaries(
            st.one_of(st.sampled_from(RESET_OPTION_KEYS), st.text(max_size=4)),
            anything,
            max_size=5,
        ),
        st.fixed_dictionaries(
            {"q": st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6)},
            optional={
                "qd": st.lists(numbers, min_size=6, max_size=6),
                "mode": anything,
                "stance_side": anything,
                "root_y": anything,
            },
        ),
    )
)
def test_reset_options_are_refused_by_name_or_run(options):
    env = ConstrainedBipedEnv()
    try:
        obs, _ = env.reset(seed=0, options=options)
    except (ValueError, TypeError) as e:
        names = [*options, "dict", "'q'"] if isinstance(options, dict) else ["dict"]
        assert _names_one_of(e, names), f"{type(e).__name__}: {e} (options {options!r})"
        return
    _check_finite(env, obs)
    obs, reward, *_ = env.step(np.zeros(5))
    _check_finite(env, obs)
    assert math.isfinite(reward)


@FUZZ
@given(
    action=st.one_of(
        st.lists(numbers, max_size=7),
        st.lists(st.floats(-200.0, 200.0), min_size=5, max_size=5),
        st.text(max_size=5),
        numbers,
    ),
    dtype=st.sampled_from([None, np.float32, np.float64, np.int64, np.bool_, object]),
    out_of_range=st.sampled_from(["clip", "raise"]),
)
def test_actions_are_refused_or_run(action, dtype, out_of_range):
    env = ConstrainedBipedEnv(action={"out_of_range": out_of_range})
    env.reset(seed=0)
    try:
        a = np.asarray(action, dtype=dtype) if dtype is not None else action
    except (ValueError, TypeError, OverflowError):
        return  # numpy refused to build it: nothing reaches the env
    try:
        obs, reward, *_ = env.step(a)
    except ValueError as e:
        assert "action" in str(e), f"{e} (action {a!r})"
        return
    _check_finite(env, obs)
    assert math.isfinite(reward)


@FUZZ
@given(
    kwargs=st.dictionaries(
        st.sampled_from(["num_envs", "max_episode_steps", "num_threads", "autoreset_mode"]),
        anything,
        max_size=2,
    )
)
def test_vector_kwargs_are_refused_by_name_or_run(kwargs):
    kwargs = {"num_envs": 2, **kwargs}
    try:
        venv = gym.make_vec(
            "ConstrainedBiped-v0", vectorization_mode="vector_entry_point", **kwargs
        )
        obs, _ = venv.reset(seed=0)
        obs, reward, *_ = venv.step(np.zeros((venv.num_envs, 5)))
    except (ValueError, TypeError) as e:
        assert _names_one_of(e, kwargs), f"{type(e).__name__}: {e} (kwargs {kwargs})"
        return
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
