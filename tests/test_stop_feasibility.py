"""The stop test of the command protocol, and the stop search's rollouts judged by it."""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from training.evaluation.stop_feasibility import KD, KP, _at, rollout
from training.plumbing.command_protocol import HOLD_S, STOP_WITHIN_S, period_speeds, stands

T = np.arange(1, 601) * 0.02  # period ends over 12 s


def _speeds(rest_from: float, v_walk: float = 0.8) -> np.ndarray:
    return np.where(T < rest_from, v_walk, 0.01)


def test_stands_needs_rest_within_the_window_held_and_the_episode_running():
    t0 = 2.0
    ok, drift = stands(T, _speeds(3.0), t0, T[-1])
    assert ok and drift == pytest.approx(0.01)
    # at rest only after STOP_WITHIN_S: no
    assert not stands(T, _speeds(t0 + STOP_WITHIN_S + 0.1), t0, T[-1])[0]
    # the episode ended before the hold did: no
    assert not stands(T, _speeds(3.0), t0, t0 + STOP_WITHIN_S + HOLD_S - 0.5)[0]
    # one period in the hold at 0.12 m/s (over twice the rest speed): no
    v = _speeds(3.0)
    v[np.searchsorted(T, 5.0)] = 0.12
    assert not stands(T, v, t0, T[-1])[0]
    # a speed crossing zero on the way to rest (one calm period, then moving) does not hide
    # the rest that follows within the window
    v = _speeds(3.0)
    v[np.searchsorted(T, 2.5)] = 0.0
    assert stands(T, v, t0, T[-1])[0]
    # never at rest: the drift is infinite
    ok, drift = stands(T, np.full_like(T, 0.3), t0, T[-1])
    assert not ok and drift == np.inf


def test_a_period_of_no_duration_has_no_speed_and_is_not_a_rest():
    # a walk at 1 m/s with an env step that ended at a switch at its own start (t repeated)
    t = np.array([0.0, 0.02, 0.04, 0.04, 0.06])
    t_end, v = period_speeds({"t": t, "hip_y": t * 1.0})
    np.testing.assert_allclose(t_end, [0.02, 0.04, 0.06])
    np.testing.assert_allclose(v, 1.0)


def test_knots_are_linear_between_and_held_after_the_span():
    knots = np.arange(3, dtype=float)[None, None, :].repeat(5, axis=1)  # 0, 1, 2 over 2 s
    assert _at(knots, 0.5, 2.0)[0, 0] == pytest.approx(0.5)
    assert _at(knots, 1.5, 2.0)[0, 0] == pytest.approx(1.5)
    assert _at(knots, 5.0, 2.0)[0, 0] == pytest.approx(2.0)
    two = np.concatenate([knots, 2 * knots])  # rows at their own times
    assert _at(two, np.array([0.5, 1.5]), 2.0)[:, 0] == pytest.approx([0.5, 3.0])


def test_a_pd_hold_of_the_standing_start_stands_and_a_shove_does_not():
    env = gym.make("ConstrainedBiped-v0", task="command", start="stand")
    env.reset(seed=1)
    st = env.unwrapped.state
    start = {"q": st.q.tolist(), "qd": st.qd.tolist(), "mode": int(st.mode),
             "stance_side": int(st.stance_side), "root_y": float(st.root_y)}  # fmt: skip
    venv = gym.make_vec("ConstrainedBiped-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        task="command", termination={"time_limit_s": None})  # fmt: skip
    k = 3
    target = np.broadcast_to(np.asarray(st.q[1:])[None, :, None], (2, 5, k)).copy()
    ff = np.zeros((2, 5, k))
    ff[1, 0, :2] = 150.0  # row 1: the stance ankle at the torque limit for the first second
    t, v, alive_to = rollout(venv, start, target, ff, 2.0, STOP_WITHIN_S + HOLD_S)
    assert (KP, KD) == (100.0, 10.0)
    ok0, drift0 = stands(t, np.nan_to_num(v[0], nan=1.0), 0.0, alive_to[0])
    ok1, _ = stands(t, np.nan_to_num(v[1], nan=1.0), 0.0, alive_to[1])
    assert ok0 and drift0 < 0.01 and alive_to[0] == pytest.approx(STOP_WITHIN_S + HOLD_S)
    moved = np.abs(np.nan_to_num(v[1], nan=0.0)).max() > 0.1
    assert not ok1 and (alive_to[1] < STOP_WITHIN_S + HOLD_S or moved)  # ended it, or moved it
