"""Bad input is refused with an error that names it; the episode discipline is enforced.

Each case here was reproduced as a silent coercion, a hang, a raw traceback from deep inside,
or a step that ran on when it should not have.
"""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env import starts
from biped_constraint_env.env import ENV_ARGUMENTS, ConstrainedBipedEnv
from biped_constraint_env.starts import NOMINAL_POSTURE_RAD
from biped_constraint_env.stepper import H_MIN_S, _next_step

POSTURE = list(NOMINAL_POSTURE_RAD)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"physics": {"strict": 0.5}}, "strict"),
        ({"physics": {"strict": "0"}}, "strict"),
        ({"physics": {"strict": "no"}}, "strict"),
        ({"physics": {"locate_events": 1}}, "locate_events"),
        ({"physics": {"stop_at_switch": "yes"}}, "stop_at_switch"),
        ({"dt": True}, "dt"),
        ({"dt": 1e308}, "dt"),
        ({"dt": float("nan")}, "dt"),
        ({"physics": {"substeps": 10**9}}, "substeps"),
        ({"physics": {"substeps": 2**64}}, "substeps"),
        ({"physics": {"substeps": 2.0}}, "substeps"),
        ({"physics": {"step_tol": 1e-30}}, "step_tol"),
        ({"params": "x"}, "params"),
        ({"action": {"torque_limit_nm": 1e-170}}, "torque_limit_nm"),
        ({"action": {"torque_limit_nm": True}}, "torque_limit_nm"),
        ({"start": {"reset_noise_scale": 9e307}}, "reset_noise_scale"),
        ({"start": {"posture": [str(x) for x in POSTURE]}}, "posture"),
        ({"start": {"posture": [True] * 6}}, "posture"),
        ({"reward": {"weights": {"alive": float("inf")}}}, "alive"),
        ({"termination": {"fall_hip_height_m": "1"}}, "fall_hip_height_m"),
        ({"task": 1}, "task"),
        ({"preset": None, "physics": {"integrator": True}}, "integrator"),
        ({"action": {"out_of_range": "wrap"}}, "out_of_range"),
    ],
)
def test_bad_make_kwarg_is_refused_by_name(kwargs, name):
    with pytest.raises(ValueError, match=name):
        gym.make("ConstrainedBiped-v0", **kwargs)


@pytest.mark.parametrize(
    ("old", "where"),
    [("strict", "physics={'strict'"), ("stop_at_switch", "physics={'stop_at_switch'"),
     ("torque_limit_nm", "action={'torque_limit_nm'"), ("rsi", "{'reference': 0.5"),
     ("posture", "start={'posture'"), ("time_limit_s", "termination={'time_limit_s'"),
     ("phase_obs", "observation=['phase']"), ("alive_bonus", "'weights': {'alive'")],
)  # fmt: skip
def test_a_flat_keyword_of_a_part_is_refused_naming_its_new_place(old, where):
    """One keyword per part: each old flat keyword names the part that now holds it."""
    with pytest.raises(ValueError, match="one keyword per part") as e:
        gym.make("ConstrainedBiped-v0", **{old: 1.0})
    assert where in str(e.value) and len(str(e.value).splitlines()) == 1


def test_the_env_takes_one_keyword_per_part():
    assert set(ENV_ARGUMENTS) == {"task", "preset", "dt", "params", "physics", "action", "start",
                                  "reward", "termination", "observation", "perturbations",
                                  "command", "reference", "render_mode"}  # fmt: skip


def test_misspelt_kwarg_lists_the_valid_names():
    with pytest.raises(ValueError) as e:
        gym.make("ConstrainedBiped-v0", physcs={"strict": True})
    msg = str(e.value)
    assert "'physcs'" in msg and "did you mean 'physics'" in msg
    assert all(name in msg for name in ENV_ARGUMENTS)


@pytest.mark.parametrize(
    ("options", "name"),
    [
        ("q", "dict"),
        ({"q": POSTURE, "stance_side": 1.9}, "stance_side"),
        ({"q": POSTURE, "stance_side": True}, "stance_side"),
        ({"q": POSTURE, "mode": 1.0}, "mode"),
        ({"q": [str(x) for x in POSTURE]}, "q"),
        ({"q": POSTURE, "qd": [1e300] * 6}, "qd"),
        ({"q": POSTURE, "qd": [float("nan")] * 6}, "qd"),
        ({"q": POSTURE, "root_y": "0"}, "root_y"),
        ({"q": POSTURE, "velocity": 0}, "valid: command, mode, q, qd, root_y, stance_side"),
    ],
)
def test_bad_reset_option_is_refused_by_name(options, name):
    env = ConstrainedBipedEnv()
    with pytest.raises(ValueError, match=name):
        env.reset(options=options)


def test_step_needs_a_reset_first_and_after_every_end():
    env = ConstrainedBipedEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(5))
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(np.zeros(5))  # zero torque: an out-of-model event
    assert terminated and info["termination_reason"]
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(5))
    env.reset(seed=0)
    with pytest.raises(ValueError):
        env.reset(options={"q": POSTURE, "mode": 7})
    with pytest.raises(RuntimeError, match="reset"):  # a refused reset starts no episode
        env.step(np.zeros(5))


def test_fall_termination_ends_the_episode_for_step():
    env = ConstrainedBipedEnv(
        termination={"fall_hip_height_m": 10.0}
    )  # the hip is always below 10 m
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(np.zeros(5))
    assert terminated
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(5))


def test_vector_env_step_needs_a_reset_first():
    venv = gym.make_vec("ConstrainedBiped-v0", num_envs=2, vectorization_mode="vector_entry_point")
    with pytest.raises(RuntimeError, match="reset"):
        venv.step(np.zeros((2, 5)))


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"max_episode_steps": "x"}, "max_episode_steps"),
        ({"num_envs": 0}, "num_envs"),
        ({"num_threads": 0}, "num_threads"),
        ({"autoreset_mode": "never"}, "autoreset_mode"),
        ({"physcs": {"strict": True}}, "physcs"),
    ],
)
def test_bad_vector_kwarg_is_refused_by_name(kwargs, name):
    kwargs = {"num_envs": 2, **kwargs}
    with pytest.raises(ValueError, match=name):
        gym.make_vec("ConstrainedBiped-v0", vectorization_mode="vector_entry_point", **kwargs)


def test_large_reset_noise_redraws_instead_of_failing_the_batch(monkeypatch):
    """An automatic reset that draws a start below the ground draws again (same in both envs)."""
    draws = []
    sample = starts.sample_start
    monkeypatch.setattr(starts, "sample_start", lambda *a: draws.append(1) or sample(*a))
    kw = {"start": {"reset_noise_scale": 0.4}}
    n = 12
    venv = gym.make_vec(
        "ConstrainedBiped-v0", num_envs=n, vectorization_mode="vector_entry_point", **kw
    )
    obs, _ = venv.reset(seed=3)
    resets = n
    for _ in range(20):  # zero torques end episodes at once: many automatic resets
        obs, _, term, trunc, _ = venv.step(np.zeros((n, 5)))
        resets += int(np.sum(term | trunc))
    assert np.all(np.isfinite(obs))
    assert len(draws) > resets  # some starts were drawn again
    single = [gym.make("ConstrainedBiped-v0", **kw).unwrapped for _ in range(n)]
    first = np.array([e.reset(seed=3 + i)[0] for i, e in enumerate(single)])
    np.testing.assert_array_equal(first, venv.reset(seed=3)[0])


def test_hopeless_reset_noise_is_refused_by_name(monkeypatch):
    monkeypatch.setattr(starts, "MAX_START_DRAWS", 1)
    env = ConstrainedBipedEnv(start={"reset_noise_scale": 1.0})
    with pytest.raises(ValueError, match="reset_noise_scale"):
        for seed in range(50):
            env.reset(seed=seed)


def test_the_error_controller_never_proposes_a_step_below_its_floor():
    """A step accepted at the floor with a huge error estimate used to propose ever shorter
    steps: ``step_tol=1e-30`` hung a single ``env.step`` for minutes."""
    accepted, nxt = _next_step(1e30, H_MIN_S, H_MIN_S, 5e-3, 4)
    assert accepted and nxt >= H_MIN_S
    accepted, nxt = _next_step(1e30, H_MIN_S, 2 * H_MIN_S, 5e-3, 4)
    assert accepted and nxt >= H_MIN_S


def test_smallest_step_tolerance_finishes_a_period():
    env = ConstrainedBipedEnv(physics={"step_tol": 1e-8}, start="rest")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(5))
    assert info["t"] > 0


@pytest.mark.parametrize("seed", [1.5, True, -1, "3", [1, 2.5]])
def test_reset_refuses_a_seed_that_is_not_an_int(seed):
    import gymnasium as gym

    venv = gym.make_vec("ConstrainedBiped-v0", 2, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=seed)
    if not isinstance(seed, list):
        with pytest.raises(ValueError, match="seed"):
            gym.make("ConstrainedBiped-v0").reset(seed=seed)
