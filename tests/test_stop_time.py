"""The ``max_stop_s`` termination: still moving after a zero command's grace time ends it."""

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.terminations import STOP_SPEED_M_S
from training.ppo.policy_io import load_policy, policy_batch_actor

POLICY = Path(__file__).resolve().parents[1] / "policies" / "ppo_command_50hz"
GRACE_S, ZERO_AT_S = 1.0, 3.0


def _walk_then_zero(n_rows: int, zero_rows):
    """The command policy from rest at 1.0 m/s, then 0 in ``zero_rows`` from ZERO_AT_S.

    Per row: None, or (the time from the zero command to the end [s], the reason).
    """
    policy, norm, cfg, _ = load_policy(POLICY)
    act = policy_batch_actor(policy, norm, cfg)
    kw = {**cfg.env_kwargs(), "start": "rest", "termination": {"max_stop_s": GRACE_S}}
    if n_rows == 1:
        env = gym.make(cfg.env_id, **kw)
        obs, info = env.reset(seed=700000, options={"command": 1.0})
        obs, set_cmd = obs[None, :], env.unwrapped.set_command
    else:
        env = gym.make_vec(cfg.env_id, num_envs=n_rows, vectorization_mode="vector_entry_point",
                           **kw)  # fmt: skip
        obs, info = env.reset(seed=700000, options={"command": 1.0})
        set_cmd = env.unwrapped.set_command
    ends, zeroed = [None] * n_rows, None
    t = np.zeros(n_rows)  # each row's simulated time (a period may end early at a switch)
    while t.min() < ZERO_AT_S + 3.0 and any(e is None for e in ends):
        if zeroed is None and t.min() >= ZERO_AT_S:
            cmd = np.ones(n_rows)
            cmd[list(zero_rows)] = 0.0
            set_cmd(cmd[0] if n_rows == 1 else cmd)
            zeroed = t.copy()
        tau = act(obs)
        obs, _, te, tr, info = env.step(tau[0] if n_rows == 1 else tau)
        obs = np.atleast_2d(obs)
        for i in range(n_rows):
            done = te if n_rows == 1 else te[i]
            if ends[i] is None and done:
                reason = info["termination_reason"]
                ti = info["t"] if n_rows == 1 else info["t"][i]
                ends[i] = (round(float(ti - zeroed[i]), 6), reason if n_rows == 1 else reason[i])
        t = np.atleast_1d(np.asarray(info["t"], dtype=float))
    env.close()
    return ends


def test_walking_on_through_a_zero_command_ends_after_the_grace_time_alike_in_both_envs():
    (single,) = _walk_then_zero(1, [0])
    t, reason = single
    assert reason == "stop_time"
    assert GRACE_S < t <= GRACE_S + 0.3  # walking on: over 0.1 m/s, ended right after
    batched = _walk_then_zero(2, [0])
    assert batched[0][1] == reason and batched[0][0] == pytest.approx(t, abs=1e-5)  # same episode
    assert batched[1] is None  # the row still commanded 1.0 m/s walks on


def test_standing_still_at_a_zero_command_never_ends_by_it():
    env = gym.make("ConstrainedBiped-v0", task="command", start="stand",
                   termination={"max_stop_s": 0.2})  # fmt: skip
    env.reset(seed=1, options={"command": 0.0})
    u = env.unwrapped
    q0 = u.state.q.copy()
    for _ in range(150):  # 3 s of the PD hold that keeps this start in model 4
        st = u.state
        tau = np.clip(-100 * (st.q[1:] - q0[1:]) - 10 * st.qd[1:], -150, 150)
        _, _, te, tr, info = env.step(tau.astype(np.float32))
        assert not te and not tr, info["termination_reason"]
    from training.plumbing.command_protocol import STAND_SPEED_M_S

    assert STOP_SPEED_M_S == 2 * STAND_SPEED_M_S  # the protocol's bound on a stand's periods


def test_it_needs_a_command_and_a_positive_time():
    from biped_constraint_env.settings import make_settings

    with pytest.raises(ValueError, match="max_stop_s needs a command"):
        make_settings(termination={"max_stop_s": 1.0})  # refused by the settings, before any run
    with pytest.raises(ValueError, match="max_stop_s needs a command"):
        gym.make("ConstrainedBiped-v0", termination={"max_stop_s": 1.0})
    with pytest.raises(ValueError, match="max_stop_s"):
        gym.make("ConstrainedBiped-v0", task="command", termination={"max_stop_s": 0.0})
