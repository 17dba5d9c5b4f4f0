"""Episodes run all at once in the batched env equal the single env's, seed by seed."""

from __future__ import annotations

import numpy as np
import pytest

from training.controller.model_controller import ModelController
from training.plumbing.rollouts import run_episodes, run_episodes_batched

KEYS = ("seed", "steps_completed", "end")


def _check_equal(single, batched):
    assert [[e[k] for k in KEYS] for e in batched] == [[e[k] for k in KEYS] for e in single]
    for key in ("distance_m", "return", "t_s", "cost_of_transport"):
        np.testing.assert_allclose(
            [e[key] for e in batched], [e[key] for e in single], rtol=1e-9, atol=1e-9, err_msg=key
        )
    for b, s in zip(batched, single, strict=True):  # the steps' times and hip positions
        np.testing.assert_allclose(b["step_t_s"], s["step_t_s"], atol=1e-9)
        np.testing.assert_allclose(b["step_hip_y_m"], s["step_hip_y_m"], atol=1e-9)


def test_batched_episodes_of_different_lengths_equal_single_ones():
    """The model controller with a state-dependent 1 N m disturbance on the stance ankle, 3 s
    from six seeded mid-stride starts: some episodes fall before the time limit and some walk
    to it; each has the single env's steps, distance, return, duration and end."""
    ctl = ModelController()

    def shaky(obs):
        return ctl(obs) + np.sin(1e3 * obs[..., :1]) * np.eye(5)[0]

    kw = {"max_episode_steps": 600}
    seeds = [1, 2, 3, 4, 5, 10_000]
    single = run_episodes(shaky, kw, seeds)
    batched = run_episodes_batched(shaky, kw, seeds)
    _check_equal(single, batched)
    ends = {e["end"] for e in batched}
    assert "time_limit" in ends and len(ends) > 1, ends  # both kinds of episode are covered
    assert max(e["steps_completed"] for e in batched) >= 3


def test_batched_episodes_that_end_at_once_equal_single_ones():
    """Zero torques end every mid-stride start in its first period, as in the single env."""
    zero = lambda obs: np.zeros(obs.shape[:-1] + (5,))  # noqa: E731
    seeds = [1, 2, 3, 4]
    single = run_episodes(zero, {}, seeds)
    batched = run_episodes_batched(zero, {}, seeds)
    _check_equal(single, batched)
    assert all(e["t_s"] < 0.01 and e["end"] != "time_limit" for e in batched)


def test_report_episodes_last_30_s_at_any_control_period():
    """``episode_s``: the time limit in seconds (1500 periods at 20 ms, not the registered
    6000 periods, which would be 120 s)."""
    kw = {"task": "track", "dt": 0.02, "start": "midstride"}
    (ep,) = run_episodes_batched(lambda o: np.zeros((len(o), 5)), kw, [0], episode_s=0.1)
    assert ep["end"] == "time_limit" and ep["t_s"] == pytest.approx(0.1)
