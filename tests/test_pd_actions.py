"""The action mappings: PD targets held over the control period, the PD law at the physics rate.

And the torque action unchanged: its trajectories equal ones recorded before the PD law moved
into the compiled period (tests/data/torque_reference.npz, recorded with the teacher's torques).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.actions import PD_FIXED_POSE_RAD, PD_KD, PD_KP, check_pd_dt

DATA = Path(__file__).parent / "data" / "torque_reference.npz"
ACTION = np.array([0.1, -0.1, 0.2, 0.1, -0.05])


def _pd_run(dt: float, pd_dt: float, periods: int, action=ACTION) -> np.ndarray:
    """(q, q-dot) after ``periods`` of a constant PD action from rest (no noise)."""
    env = gym.make(
        "ConstrainedBiped-v0", dt=dt, action={"kind": "pd", "dt": pd_dt},
        start={"kind": "rest", "reset_noise_scale": 0.0}, physics={"stop_at_switch": False},
    )  # fmt: skip
    env.reset(seed=0)
    for _ in range(periods):
        _, _, terminated, _, info = env.step(action)
        assert not terminated, info["termination_reason"]
    s = env.unwrapped.state
    return np.concatenate([s.q, s.qd])


def test_decimation_one_period_of_held_targets_is_many_short_ones():
    """Targets held over 20 ms with the PD law every 2 ms are ten 2 ms periods exactly (2 ms:
    the shortest control period an env accepts); with the law every 5 ms they stay close,
    while the PD torque held for 20 ms is far off."""
    fine = _pd_run(0.002, 0.002, 10)
    assert np.array_equal(_pd_run(0.02, 0.002, 1), fine)
    physics_rate = np.abs(_pd_run(0.02, 0.005, 1) - fine).max()
    held = np.abs(_pd_run(0.02, 0.02, 1) - fine).max()
    assert physics_rate < held / 5, (physics_rate, held)


def test_pd_at_the_period_is_the_held_torque_law():
    """``pd_dt = dt``: the PD torque of the period's first state, held (the torque env with
    that torque gives the same trajectory, bit for bit)."""
    pd = gym.make("ConstrainedBiped-v0", action={"kind": "pd", "dt": 0.005}, start="rest")
    tq = gym.make("ConstrainedBiped-v0", start="rest")
    pd.reset(seed=1)
    tq.reset(seed=1)
    target = PD_FIXED_POSE_RAD + 1.0 * ACTION
    for _ in range(40):
        s = tq.unwrapped.state
        tau = np.clip(PD_KP * (target - s.q[1:]) + PD_KD * (0.0 - s.qd[1:]), -150, 150)
        o1, r1, t1, _, i1 = pd.step(ACTION)
        o2, r2, t2, _, _ = tq.step(tau)
        assert np.array_equal(o1, o2) and r1 == r2 and t1 == t2
        assert np.array_equal(i1["torque"], tau)
        if t1:
            break


def test_pd_torque_limit_applies_at_every_physics_step():
    env = gym.make(
        "ConstrainedBiped-v0", dt=0.02, start="rest",
        action={"kind": "pd", "gain_scale": 100.0, "torque_limit_nm": 40.0},
    )  # fmt: skip
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.ones(5))
    assert np.all(np.abs(info["torque"]) <= 40.0 + 1e-12)
    terms = [info[k] for k in info if k.startswith("reward_")]
    assert reward == pytest.approx(sum(terms), abs=1e-12)


REFERENCE_PD = {"action": {"kind": "pd", "around": "reference"}, "reward": "tracking"}


@pytest.mark.parametrize("kw", [{}, REFERENCE_PD])
def test_pd_single_equals_batched_at_the_physics_rate(kw):
    kw = {"action": "pd", "dt": 0.02, "start": "rest", **kw}
    venv = gym.make_vec("ConstrainedBiped-v0", 3, vectorization_mode="vector_entry_point", **kw)
    envs = [gym.make("ConstrainedBiped-v0", **kw) for _ in range(3)]
    vo, _ = venv.reset(seed=4)
    for i, e in enumerate(envs):
        assert np.array_equal(e.reset(seed=4 + i)[0], vo[i])
    rng = np.random.default_rng(0)
    live = np.ones(3, bool)
    for _ in range(30):
        a = rng.uniform(-0.05, 0.05, (3, 5))
        vo, vr, vt, _, vi = venv.step(a)
        for i, e in enumerate(envs):
            if not live[i]:
                continue
            o, r, t, _, info = e.step(a[i])
            assert np.array_equal(o, vo[i]) and r == vr[i] and t == vt[i]
            assert np.array_equal(info["torque"], vi["torque"][i])
            live[i] = not t
        if not live.any():
            break


@pytest.mark.parametrize(
    ("pd_dt", "dt", "match"),
    [
        (0.003, 0.005, "divide"),
        (0.01, 0.005, "pd_dt"),
        (-1.0, 0.005, "pd_dt"),
        (0.0, 0.02, "pd_dt"),
    ],
)
def test_pd_dt_is_checked(pd_dt, dt, match):
    with pytest.raises(ValueError, match=match):
        check_pd_dt(pd_dt, dt)
    with pytest.raises(ValueError, match=match):
        gym.make("ConstrainedBiped-v0", action={"kind": "pd", "dt": pd_dt}, dt=dt)


def test_pd_dt_default_is_the_physics_step():
    assert check_pd_dt(None, 0.005) == 1 and check_pd_dt(None, 0.02) == 4
    assert check_pd_dt(None, 0.002) == 1 and check_pd_dt(0.001, 0.02) == 20


def test_torque_actions_reproduce_the_recorded_trajectories():
    ref = np.load(DATA)
    for name, kw in (("walk", {}), ("paper", {"task": "paper"})):
        env = gym.make("ConstrainedBiped-v0", **kw)
        obs, _ = env.reset(seed=7)
        for a, want in zip(ref[f"{name}_actions"], ref[f"{name}_rows"], strict=True):
            obs, r, t, _, info = env.step(a)
            got = np.concatenate([obs, [r, info["t"], info["steps_completed"]]])
            assert np.array_equal(got, want), name
    venv = gym.make_vec("ConstrainedBiped-v0", 3, vectorization_mode="vector_entry_point")
    venv.reset(seed=7)
    for a, want in zip(ref["walk_actions"][:300], ref["batched_rows"], strict=True):
        obs, r, *_ = venv.step(np.repeat(a[None], 3, 0))
        assert np.array_equal(np.concatenate([obs, r[:, None]], 1), want)


@pytest.mark.parametrize("kw", [{"action": "pd", "start": "rest"}, {"task": "track"}])
def test_the_sb3_adapter_passes_pd_targets_through(kw):
    """An SB3 action of 0.5 is the env's PD action 0.5, not 75 clipped to 1."""
    from training.ppo.sb3_vec import make_sb3_vec_env

    venv = make_sb3_vec_env(2, 0, kw, "batched")
    venv.reset()
    venv.step_async(np.full((2, 5), 0.5, np.float32))
    obs, _, _, _ = venv.step_wait()
    env = gym.make("ConstrainedBiped-v0", **kw)
    env.reset(seed=0)
    want, _, _, _, _ = env.step(np.full(5, 0.5))
    assert np.array_equal(obs[0], want.astype(np.float32))
