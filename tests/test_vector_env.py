"""Batched vector env against N single envs; sync and async make_vec modes."""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.observation import OBS_NAMES

ENV_ID = "ConstrainedBiped-v0"
V1 = {"task": "paper", "preset": "default"}  # rest start, 20 ms: long episodes under +-8 N m


def _run(mode, n_envs, steps, seed=3):
    ve = gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode=mode, **V1)
    obs, _ = ve.reset(seed=seed)
    rng = np.random.default_rng(0)
    obs_seq, R, T = [obs], [], []
    for _ in range(steps):
        obs, r, te, tr, info = ve.step(rng.uniform(-8, 8, (n_envs, 5)).astype(np.float32))
        obs_seq.append(obs)
        R.append(r)
        T.append(te | tr)
    ve.close()
    return np.array(obs_seq), np.array(R), np.array(T)


@pytest.mark.parametrize("n_envs", [3, 9])  # below and above the parallel-kernel threshold
def test_batched_equals_single_envs(n_envs):
    ob, rb, tb = _run("vector_entry_point", n_envs, 120)
    os_, rs, ts = _run("sync", n_envs, 120)
    assert tb.any()  # autoreset exercised
    assert np.array_equal(ob, os_) and np.array_equal(rb, rs) and np.array_equal(tb, ts)


def test_two_numba_threads_give_the_batched_env_the_same_numbers():
    """num_threads=2 (the parallel kernel, rows split in chunks) equals the serial kernel,
    bit for bit, through falls and resets (train_ppo --env-threads 2 changes nothing else)."""
    kw = dict(num_envs=16, vectorization_mode="vector_entry_point", dt=0.02, start="midstride")
    out = []
    for threads in (1, 2):
        ve = gym.make_vec(ENV_ID, num_threads=threads, **kw)
        obs, _ = ve.reset(seed=5)
        rng = np.random.default_rng(1)
        seq = [obs]
        for _ in range(150):
            obs, r, te, tr, _ = ve.step(rng.uniform(-0.3, 0.3, (16, 5)).astype(np.float32))
            seq += [obs, r, te | tr]
        ve.close()
        out.append(seq)
    assert any(x.any() for x in out[0][3::3])  # resets exercised
    assert all(np.array_equal(a, b) for a, b in zip(*out, strict=True))


def test_async_matches_sync():
    oa, ra, _ = _run("async", 2, 40)
    os_, rs, _ = _run("sync", 2, 40)
    assert np.array_equal(oa, os_) and np.array_equal(ra, rs)


def test_batched_truncation_and_infos():
    ve = gym.make_vec(
        ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=2, **V1
    )
    ve.reset(seed=0)
    _, _, te, tr, _ = ve.step(np.zeros((2, 5), np.float32))
    assert not tr.any()
    _, _, te, tr, info = ve.step(np.zeros((2, 5), np.float32))
    assert tr.all() and not te.any()
    assert set(info) >= {"mode", "steps_completed", "termination_reason", "reward_forward"}


def test_batched_bad_actions():
    ve = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point")
    ve.reset(seed=0)
    with pytest.raises(ValueError):
        ve.step(np.zeros((3, 5)))
    with pytest.raises(ValueError, match="finite"):
        ve.step(np.full((2, 5), np.nan))


def test_same_step_autoreset_matches_next_step():
    """SAME_STEP returns the reset observation at once and the final one in info."""
    from gymnasium.vector import AutoresetMode

    kw = dict(num_envs=3, vectorization_mode="vector_entry_point", **V1)
    nxt = gym.make_vec(ENV_ID, **kw)
    same = gym.make_vec(ENV_ID, autoreset_mode=AutoresetMode.SAME_STEP, **kw)
    nxt.reset(seed=1)
    same.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(300):
        a = rng.uniform(-8, 8, (3, 5)).astype(np.float32)
        o1, r1, t1, u1, _ = nxt.step(a)
        o2, r2, t2, u2, i2 = same.step(a)
        assert np.array_equal(r1, r2) and np.array_equal(t1, t2) and np.array_equal(u1, u2)
        done = t1 | u1
        if done.any():
            break
        assert np.array_equal(o1, o2)
    assert done.any()
    for i in np.flatnonzero(done):
        assert np.array_equal(i2["final_obs"][i], o1[i])
    o1_reset, r_reset, *_ = nxt.step(a)  # NEXT_STEP resets the finished ones now
    assert np.array_equal(o1_reset[done], o2[done]) and np.all(r_reset[done] == 0.0)


def test_fall_termination_same_in_batched_and_single():
    kw = dict(num_envs=3, termination={"fall_hip_height_m": 2.7}, **V1)
    ob, rb, tb = _run_kw("vector_entry_point", kw)
    os_, rs, ts = _run_kw("sync", kw)
    assert tb.any() and np.array_equal(ob, os_) and np.array_equal(rb, rs)


def test_midstride_start_same_in_batched_and_single():
    """The default walking task (mid-stride start, 5 ms, stop at switches): batched = single."""
    kw = dict(num_envs=3)
    ob, rb, tb = _run_kw("vector_entry_point", kw, steps=150)
    os_, rs, ts = _run_kw("sync", kw, steps=150)
    assert np.all(ob[0, :, OBS_NAMES.index("mode_2")] == 1.0)  # every slot starts in model 2
    assert tb.any() and np.array_equal(ob, os_) and np.array_equal(rb, rs)


def test_limex_same_in_batched_and_single():
    """The L-stable LIMEX integrator: batched = single, bit for bit."""
    kw = dict(num_envs=3, physics={"integrator": "limex", "substeps": 2})
    ob, rb, tb = _run_kw("vector_entry_point", kw, steps=150)
    os_, rs, ts = _run_kw("sync", kw, steps=150)
    assert tb.any() and np.array_equal(ob, os_) and np.array_equal(rb, rs)


def test_rk4_limex_same_in_batched_and_single():
    """The stiffness-switching integrator with explicit substeps: batched = single, bit for bit."""
    kw = dict(num_envs=3, physics={"integrator": "rk4_limex", "substeps": 1})
    ob, rb, tb = _run_kw("vector_entry_point", kw, steps=150)
    os_, rs, ts = _run_kw("sync", kw, steps=150)
    assert tb.any() and np.array_equal(ob, os_) and np.array_equal(rb, rs)


def _run_kw(mode, kw, steps=60, seed=3):
    ve = gym.make_vec(ENV_ID, vectorization_mode=mode, **kw)
    obs, _ = ve.reset(seed=seed)
    rng = np.random.default_rng(0)
    obs_seq, R, T = [obs], [], []
    for _ in range(steps):
        obs, r, te, tr, info = ve.step(rng.uniform(-8, 8, (kw["num_envs"], 5)).astype(np.float32))
        obs_seq.append(obs)
        R.append(r)
        T.append(te | tr)
    return np.array(obs_seq), np.array(R), np.array(T)


def test_info_keys_give_those_keys_with_the_same_values_and_refuse_unknown_ones():
    kw = {"dt": 0.02, "observation": ["phase"], "reward": {"kind": "gait"}}
    keys = ("steps_completed", "hip_y", "termination_reason")
    out = []
    for info_keys in (None, keys):
        venv = gym.make_vec("ConstrainedBiped-v0", 4, vectorization_mode="vector_entry_point",
                            autoreset_mode="SameStep", info_keys=info_keys, **kw)  # fmt: skip
        _, info = venv.reset(seed=5)
        rows = [info]
        rng = np.random.default_rng(1)
        for _ in range(30):  # random torques: episodes end and restart
            rows.append(venv.step(rng.uniform(-20, 20, (4, 5)))[4])
        out.append(rows)
    ended = 0
    for full, few in zip(*out, strict=True):
        assert {k for k in few if not k.startswith("_")} <= set(keys) | {"final_obs",
                                                                      "final_info"}  # fmt: skip
        for k in keys:
            np.testing.assert_array_equal(full[k], few[k])
        if "final_info" in few:
            ended += 1
            for i in np.flatnonzero(few["_final_info"]):
                assert few["final_info"][i] == {k: full["final_info"][i][k] for k in keys}
    assert ended > 0
    for bad, match in ((("hip_y", "nope"), "nope"), ("hip_y", "sequence"), ((1,), "sequence")):
        with pytest.raises(ValueError, match=match):
            gym.make_vec("ConstrainedBiped-v0", 2, vectorization_mode="vector_entry_point",
                         info_keys=bad)  # fmt: skip


def test_the_sb3_adapter_gives_the_single_envs_numbers_and_infos():
    """BatchedSB3VecEnv (the batched env, its few info keys) against SB3's DummyVecEnv of
    single envs: observations, rewards, dones and every info entry a learner reads."""
    from training.ppo.sb3_vec import make_sb3_vec_env

    kw = {"dt": 0.02, "observation": ["phase"], "reward": {"kind": "gait", "gated": True},
          "start": {"stride": 0.75, "midstride": 0.25}}  # fmt: skip
    runs = []
    for vec in ("batched", "dummy"):
        venv = make_sb3_vec_env(4, 11, kw, vec, max_episode_steps=12)
        rows = [venv.reset()]
        rng = np.random.default_rng(2)
        for _ in range(60):  # about the recipes' first actions: some fall, some reach the limit
            a = np.array([0.08, 0, 0, 0, 0]) + rng.uniform(-0.01, 0.01, (4, 5))
            rows.append(venv.step(a.astype(np.float32)))
        venv.close()
        runs.append(rows)
    np.testing.assert_array_equal(runs[0][0], runs[1][0].astype(np.float32))
    truncated = ended = 0
    for (o1, r1, d1, i1), (o2, r2, d2, i2) in zip(runs[0][1:], runs[1][1:], strict=True):
        np.testing.assert_array_equal(o1, o2.astype(np.float32))
        np.testing.assert_array_equal(r1, r2.astype(np.float32))
        np.testing.assert_array_equal(d1, d2)
        for a, b in zip(i1, i2, strict=True):
            for k in ("steps_completed", "hip_y", "termination_reason"):
                assert a[k] == b[k], k
            if "terminal_observation" in b:
                ended += 1
                truncated += b["TimeLimit.truncated"]
                assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
                np.testing.assert_array_equal(
                    a["terminal_observation"], b["terminal_observation"].astype(np.float32)
                )
    assert ended > truncated > 0
