"""Restarts from the env's own states (``restarts``): what the pool keeps, where resets start,
and the single env equal to a batch of one."""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.restarts import RestartPool
from training.controller.model_controller import controller_from


def _walk(env, obs, periods, teacher):
    for _ in range(periods):
        obs, _, term, trunc, info = env.step(teacher(obs))
        if term or trunc:
            break
    return obs, info


def test_resets_start_at_the_states_after_completed_steps():
    teacher = controller_from("model:teacher_robust")
    plain = gym.make("ConstrainedBiped-v0")
    env = gym.make("ConstrainedBiped-v0", restarts=1.0)
    pool = env.unwrapped.core.restarts
    assert plain.unwrapped.core.restarts is None
    # an empty pool: the env's own start, the same state as without restarts
    obs, info = env.reset(seed=4)
    np.testing.assert_array_equal(obs, plain.reset(seed=4)[0])
    assert info["mode"] == 2 and len(pool) == 0
    obs, info = _walk(env, obs, 800, teacher)
    assert info["termination_reason"] is None and len(pool) == info["steps_completed"] >= 3
    kept = pool.q[: len(pool)].copy()
    assert set(pool.mode[: len(pool)]) == {1}  # just after a step: the new stance foot flat
    starts = set()
    for seed in range(20):
        _, info = env.reset(seed=seed)
        st = env.unwrapped.state
        (row,) = np.flatnonzero((kept == st.q).all(axis=1))  # one of the kept states, exactly
        starts.add(int(row))
        assert info["mode"] == 1 and st.t == 0.0 and st.root_y == 0.0 and st.steps_completed == 0
        assert st.stance_side == 0
    assert len(starts) > 1  # drawn, not always the same


def test_restart_fraction_and_a_batch_of_one_equals_the_single_env():
    teacher = controller_from("model:teacher_robust")
    env = gym.make("ConstrainedBiped-v0", restarts=0.5)
    venv = gym.make_vec("ConstrainedBiped-v0", 1, vectorization_mode="vector_entry_point",
                        restarts=0.5)  # fmt: skip
    obs, _ = env.reset(seed=11)
    vobs, _ = venv.reset(seed=11)
    modes = []
    for _ in range(6):  # episodes: walk 1 s, then reset (the batch by a one-row reset)
        for _ in range(200):
            a = teacher(obs)
            obs, rew, term, _, info = env.step(a)
            vobs, vrew, vterm, _, vinfo = venv.step(a[None])
            np.testing.assert_array_equal(obs, vobs[0])
            assert rew == vrew[0] and term == vterm[0]
            if term:
                break
        seed = int(np.random.default_rng(len(modes)).integers(1000))
        obs, info = env.reset(seed=seed)
        vobs, vinfo = venv.reset(seed=seed)
        np.testing.assert_array_equal(obs, vobs[0])
        modes.append(info["mode"])
    assert set(modes) == {1, 2}  # restarts (model 1) and own mid-stride starts (model 2)


def test_the_pool_keeps_the_latest_states():
    pool = RestartPool(1.0, size=3)

    class Sim:
        q = np.arange(30.0).reshape(5, 6)
        qd = -q
        ist = np.ones((5, 4), np.int64)

    pool.record(Sim, np.arange(5))
    assert len(pool) == 3 and pool.count == 5
    np.testing.assert_array_equal(np.sort(pool.q[:, 0]), [12.0, 18.0, 24.0])  # rows 2, 3, 4
    rng = np.random.default_rng(0)
    chosen, picks = pool.draw([rng] * 4)
    assert chosen.all() and set(picks) <= {0, 1, 2}
    with pytest.raises(ValueError, match="restarts"):
        gym.make("ConstrainedBiped-v0", restarts=1.5)
