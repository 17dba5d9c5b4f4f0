"""A new start component, termination, observation block or action mapping is one entry in its
part's file.

Each test adds one (monkeypatched into the registry, as a user's own module would) and runs it
in the single and the batched env, which agree row for row.
"""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env import actions, observation, starts, terminations
from biped_constraint_env.modes import Mode
from training.controller.model_controller import controller_from


def _single_and_batched(kw, steps=5, n=3, action=None):
    """(observations, infos) of n single envs seeded 7 + i and of one batched env seeded 7."""
    act = np.zeros((n, 5)) if action is None else np.tile(action, (n, 1))
    venv = gym.make_vec("ConstrainedBiped-v0", n, vectorization_mode="vector_entry_point", **kw)
    vo, _ = venv.reset(seed=7)
    envs = [gym.make("ConstrainedBiped-v0", **kw) for _ in range(n)]
    so = np.array([e.reset(seed=7 + i)[0] for i, e in enumerate(envs)])
    np.testing.assert_array_equal(vo, so)
    reasons = []
    for _ in range(steps):
        vo, _, vterm, _, vinfo = venv.step(act)
        outs = [e.step(act[i]) for i, e in enumerate(envs)]
        assert list(vterm) == [o[2] for o in outs]
        reasons.append([o[4]["termination_reason"] for o in outs])
        assert list(vinfo["termination_reason"]) == reasons[-1]
        if any(vterm):
            break
        np.testing.assert_array_equal(vo, np.array([o[0] for o in outs]))
    return vo, reasons


def test_a_new_start_component_is_one_entry(monkeypatch):
    def crouch(rng, posture, params):  # the rest posture, knees bent a little more
        q = np.array(posture, dtype=np.float64)
        q[2] -= 0.05 + 0.05 * rng.random()
        return q, np.zeros(6), int(Mode.FOOT_FLAT)

    monkeypatch.setitem(starts.START_COMPONENTS, "crouch", crouch)
    env = gym.make("ConstrainedBiped-v0", start="crouch").unwrapped
    env.reset(seed=0)
    assert env.state.mode == 1 and env.state.q[2] < 0.1 - 0.05
    mixed = {"start": {"crouch": 0.5, "midstride": 0.5}}
    _single_and_batched(mixed)
    seen = {gym.make("ConstrainedBiped-v0", **mixed).unwrapped.reset(seed=s)[1]["mode"]
            for s in range(20)}  # fmt: skip
    assert seen == {1, 2}


def test_a_new_action_mapping_is_one_entry(monkeypatch):
    class UnitTorque(actions.TorqueActions):  # actions in [-1, 1]^5, a fraction of the limit
        unit_actions = True
        bound_name = "unit bound"

        @staticmethod
        def in_the_loop(action):
            return "network alone (torques as fractions of the limit)"

        def hooks(self, buf, sim_modes):  # computed in Python: no kernel of its own
            return [lambda a, rngs, rows: a * self.action.torque_limit_nm]

    monkeypatch.setitem(actions.ACTION_MAPPINGS, "unit_torque", UnitTorque)
    env = gym.make("ConstrainedBiped-v0", action="unit_torque")
    assert env.action_space.high.tolist() == [1.0] * 5
    assert env.unwrapped.settings.action.in_the_loop().endswith("of the limit)")
    plain = gym.make("ConstrainedBiped-v0")
    walk = controller_from("model:teacher_robust")  # torques [N m] that walk
    obs, _ = plain.reset(seed=3)
    np.testing.assert_array_equal(env.reset(seed=3)[0], obs)
    for _ in range(100):  # the same walk as the torques it maps to
        u = walk(obs) / 150.0
        a, b = env.step(u), plain.step(u * 150.0)
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:4] == b[1:4] and not (b[2] or b[3]) and a[4]["t"] == b[4]["t"]
        obs = b[0]
    assert b[4]["steps_completed"] >= 1
    u = np.array([0.02, -0.01, 0.015, 0.0, -0.005])
    _single_and_batched({"action": "unit_torque"}, action=u)
    with pytest.raises(ValueError, match="PD settings; unit_torque actions take none"):
        gym.make("ConstrainedBiped-v0", action={"kind": "unit_torque", "range": 0.5})


def test_a_new_termination_is_one_entry(monkeypatch):
    class Slow:  # ends a row whose hip moves forward slower than the limit after a period
        reason = "too_slow"

        def __init__(self, core, limit):
            self.hip, self.limit = core.hip, limit

        def __call__(self, skip):
            slow = self.hip[:, 2] < self.limit
            if skip is not None:
                slow[skip] = False
            return slow

    entry = terminations.Termination(float, Slow)
    monkeypatch.setitem(terminations.TERMINATIONS, "min_hip_speed_m_s", entry)
    kw = {"task": "paper", "preset": "default", "termination": {"min_hip_speed_m_s": 10.0}}
    _, reasons = _single_and_batched(kw)
    assert reasons[0] == ["too_slow"] * 3  # at rest: slower than 10 m/s after one period
    s = gym.make("ConstrainedBiped-v0", **kw).unwrapped.settings
    assert s.termination.as_dict()["min_hip_speed_m_s"] == 10.0


def test_a_new_observation_block_is_one_entry(monkeypatch):
    def hip_z(core):
        return core.hip[:, 1:2]

    low, high = np.array([-10.0]), np.array([10.0])
    block = observation.ObservationBlock(("hip_z_again",), low, high, hip_z)
    monkeypatch.setitem(observation.OBSERVATION_BLOCKS, "hip_z_again", block)
    kw = {"task": "paper", "preset": "default", "observation": ["phase", "hip_z_again"]}
    env = gym.make("ConstrainedBiped-v0", **kw)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (27,) and env.observation_space.shape == (27,)
    assert obs[-1] == obs[observation.OBS_NAMES.index("hip_z")]
    _single_and_batched(kw)


def test_one_record_per_period_serves_every_reward_kind():
    """The compiled period writes one record per row: the "env" terms only where they are the
    reward (zeros else, none computed and dropped), and the progress, steps and swing speed
    that the other kinds' terms read (no second compiled call)."""
    from biped_constraint_env.rewards import REC_PROGRESS, REC_STEPS, REC_SWING_VY

    for reward in ("env", "gait"):
        env = gym.make("ConstrainedBiped-v0", reward=reward, task="paper", preset="default")
        env.reset(seed=3)
        u = env.unwrapped
        y0 = u.core.hip[0, 0]
        _, r, _, _, info = env.step(np.zeros(5))
        rec = u.core.buf.rew[0]
        assert rec[REC_PROGRESS] == u.core.hip[0, 0] - y0 and rec[REC_STEPS] == 0.0
        assert np.isfinite(rec[REC_SWING_VY])
        if reward == "env":
            assert rec[5] == r and rec[0] == info["reward_forward"]
        else:
            assert (
                not rec[:6].any()
                and r
                == info["reward_speed"]
                + info["reward_height"]
                + info["reward_swing"]
                + info["reward_cadence"]
                + info["reward_step"]
            )


def test_a_new_reward_term_is_one_entry(monkeypatch):
    """A term of the gait reward: its spec and function, one registry entry; it appears in
    ``info``, its weight is a setting, and the terms still add up to the reward."""
    from biped_constraint_env.rewards import REWARD_KINDS, RewardTerm

    def upright(r, p):  # the hip no lower than 2.9 m
        return (p.hip_z > 2.9).astype(float)

    term = RewardTerm("upright", 0.5, value=upright, doc="1 while the hip is above 2.9 m")
    monkeypatch.setitem(REWARD_KINDS, "gait", (*REWARD_KINDS["gait"], term))
    kw = {
        "task": "paper",
        "preset": "default",
        "reward": {"kind": "gait", "weights": {"upright": 0.25}},
    }
    env = gym.make("ConstrainedBiped-v0", **kw)
    env.reset(seed=0)
    _, r, _, _, info = env.step(np.zeros(5))
    assert info["reward_upright"] == 0.25  # at rest, upright
    terms = [t.name for t in REWARD_KINDS["gait"]]
    assert r == pytest.approx(sum(info[f"reward_{t}"] for t in terms), abs=1e-12)
    _single_and_batched(kw)
