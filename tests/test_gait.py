"""The gait reward (``reward="gait"``): its terms against their definitions, the swing ankle's
speed against a finite difference, and a walk's reward under it (single = batched and the terms'
sum: ``test_info_parity.py``)."""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.gait import GAIT_TERMS, GaitReward
from biped_constraint_env.kinematics import keypoints, nb_swing_ankle_vy
from biped_constraint_env.model import paper_biped
from biped_constraint_env.rewards import REC_SWING_VY, REWARD_KINDS, reward_settings
from biped_constraint_env.settings import make_settings
from training.controller.model_controller import controller_from

TERMS = {t.name: t for t in REWARD_KINDS["gait"]}
SWING_ANKLE = 6  # keypoints: stance toe, heel, joints 1-5 (the swing ankle is joint 5)


def _reward(**targets):
    return GaitReward(reward_settings({"kind": "gait", "targets": targets}), 0.02, 1)


def _terms(g, progress, z, swing_vy, mode, t_model, steps=0, alive=True, switches=None):
    sw = None if switches is None else np.array([switches])
    return g.terms(np.array([progress]), np.array([z]), np.array([swing_vy]), np.array([mode]),
                   np.array([t_model]), np.array([steps]), np.array([alive]),
                   switches=sw)[0]  # fmt: skip


def test_terms_are_their_weights_at_the_targets_and_fall_as_documented():
    g = _reward()
    tg = {t: TERMS[t].target for t in TERMS if TERMS[t].target is not None}
    on = _terms(g, tg["speed"] * 0.02, tg["height"], tg["swing"], 1, tg["cadence"])
    for c, name in enumerate(GAIT_TERMS):
        if TERMS[name].per_period:  # the kernel terms
            assert on[c] == pytest.approx(TERMS[name].weight)
    assert on[-1] == pytest.approx(1.0)  # the kernel weights sum to one

    def kernel(name, e):
        return TERMS[name].weight * np.exp(-TERMS[name].kernel * e**2)

    out = _terms(g, (tg["speed"] - 0.7) * 0.02, tg["height"] + 0.1, tg["swing"] - 0.5, 2,
                 tg["cadence"] + 0.3)  # fmt: skip
    np.testing.assert_allclose(out[:4], [kernel("speed", 0.7), kernel("height", 0.1),
                                         kernel("swing", 0.5), kernel("cadence", 0.3)])  # fmt: skip
    # one-sided terms: a faster swing foot, or a shorter time in the model, is on target
    fast = _terms(g, tg["speed"] * 0.02, tg["height"], tg["swing"] + 3.0, 1, 0.0)
    assert fast[2] == pytest.approx(TERMS["swing"].weight)
    assert fast[3] == pytest.approx(TERMS["cadence"].weight)
    # the swing foot down (models 3, 4): the swing term is its weight whatever the speed
    for mode in (3, 4):
        assert _terms(g, 0.0, 0.0, -5.0, mode, 0.0)[2] == TERMS["swing"].weight
    # a period ended by an event earns its steps only
    dead = _terms(g, tg["speed"] * 0.02, tg["height"], tg["swing"], 1, 0.0, steps=1, alive=False)
    np.testing.assert_array_equal(dead[:4], 0.0)
    assert dead[4] == dead[-1] == TERMS["step"].weight and dead[5] == 0.0  # no switch given
    # the switch term (off by default): its weight per forward model switch, however the
    # period ended
    sw = GaitReward(reward_settings({"kind": "gait", "weights": {"switch": 2.5}}), 0.02, 1)
    for alive in (True, False):
        out = _terms(sw, 0.0, 0.0, 0.0, 3, 0.0, steps=1, alive=alive, switches=3)
        assert out[GAIT_TERMS.index("switch")] == 7.5
        assert out[-1] == pytest.approx(out[:-1].sum())
    assert _terms(g, 0.0, 0.0, 0.0, 3, 0.0, switches=3)[GAIT_TERMS.index("switch")] == 0.0
    # targets are the reward's settings
    assert _terms(_reward(speed=0.5), 0.5 * 0.02, 0, 0, 3, 0)[0] == TERMS["speed"].weight


def test_per_model_cadence_targets_and_the_gate():
    """A cadence target per model (1-4) is the target of the current model; ``gated`` multiplies
    the speed, height and swing terms by the cadence kernel, and changes nothing on time."""
    per = (0.6, 0.25, 0.15, 0.1)
    g = GaitReward(reward_settings({"kind": "gait", "targets": {"cadence": list(per)}}),
                   0.02, 1)  # fmt: skip
    gated = GaitReward(reward_settings({"kind": "gait", "targets": {"cadence": list(per)},
                                        "gated": True}), 0.02, 1)  # fmt: skip
    k, w = TERMS["cadence"].kernel, TERMS["cadence"].weight
    for mode, target in zip((1, 2, 3, 4), per, strict=True):
        args = (0.02, 2.9, 0.7, mode, target + 0.2)
        plain, gate = _terms(g, *args), _terms(gated, *args)
        on_time = np.exp(-k * 0.2**2)
        assert plain[3] == pytest.approx(w * on_time)
        np.testing.assert_allclose(gate[:3], plain[:3] * on_time, rtol=1e-12)
        assert gate[3] == plain[3] and gate[-1] == pytest.approx(gate[:-1].sum())
        in_time = (0.02, 2.9, 0.7, mode, target - 0.01)
        np.testing.assert_array_equal(_terms(gated, *in_time), _terms(g, *in_time))
    s = make_settings(reward={"kind": "gait", "targets": {"cadence": list(per)}, "gated": True})
    assert make_settings(reward=s.reward.as_dict()).reward == s.reward
    assert s.reward.target("cadence") == per and s.reward.gated
    with pytest.raises(ValueError, match="one number or 4"):
        make_settings(reward={"kind": "gait", "targets": {"cadence": [0.6, 0.2]}})
    with pytest.raises(ValueError, match="reward target 'speed'"):
        make_settings(reward={"kind": "gait", "targets": {"speed": [1.0, 1, 1, 1]}})
    with pytest.raises(ValueError, match="'gated' is a setting of the 'gait' and 'command'"):
        make_settings(reward={"kind": "tracking", "gated": True})
    with pytest.raises(ValueError, match="'gated' must be a bool"):
        make_settings(reward={"kind": "gait", "gated": 1})


def test_the_swing_ankle_speed_is_the_finite_difference_of_its_position():
    env = gym.make("ConstrainedBiped-v0", reward="gait")
    obs, _ = env.reset(seed=1)
    teacher = controller_from("model:teacher_robust")
    u = env.unwrapped
    params = paper_biped()
    checked = set()
    for _ in range(400):
        obs, _, term, _, info = env.step(teacher(obs))
        assert not term
        sim = u.core.sim
        q, qd, side = sim.q[0].copy(), sim.qd[0].copy(), int(sim.ist[0, 1])
        vy = u.core.buf.rew[0, REC_SWING_VY]  # the period's record
        again = np.zeros(1)
        nb_swing_ankle_vy(u.core.buf.chs, sim.q, sim.qd, sim.ist, again)
        assert vy == again[0]  # the kinematics' own routine, bit for bit
        h = 1e-6
        chain = params.chain(side)
        fd = (keypoints(chain, q + h * qd)[SWING_ANKLE, 0]
              - keypoints(chain, q - h * qd)[SWING_ANKLE, 0]) / (2 * h)  # fmt: skip
        assert vy == pytest.approx(fd, rel=1e-6, abs=1e-6)
        checked.add((info["mode"], side))
    assert {m for m, _ in checked} >= {1, 2} and {s for _, s in checked} == {0, 1}


def test_a_walk_earns_its_steps_and_the_clock_terms():
    env = gym.make("ConstrainedBiped-v0", reward="gait")
    obs, _ = env.reset(seed=2)
    teacher = controller_from("model:teacher_robust")
    steps, cadence = 0.0, []
    for _ in range(600):
        obs, rew, term, _, info = env.step(teacher(obs))
        assert not term
        steps += info["reward_step"]
        cadence.append(info["reward_cadence"])
        assert rew == pytest.approx(sum(info[f"reward_{t}"] for t in GAIT_TERMS), abs=1e-12)
    assert steps == info["steps_completed"] * TERMS["step"].weight > 0
    assert min(cadence) == TERMS["cadence"].weight  # the teacher holds no model beyond 0.7 s


def test_gait_settings_round_trip_and_bad_targets_are_refused_by_name():
    s = make_settings(reward={"kind": "gait", "targets": {"speed": 0.9}, "kernels": {"swing": 2}})
    assert make_settings(reward=s.reward.as_dict()).reward == s.reward
    assert s.reward.target("speed") == 0.9 and s.needs_clock and not s.needs_reference
    with pytest.raises(ValueError, match="did you mean 'speed'"):
        make_settings(reward={"kind": "gait", "targets": {"sped": 1.0}})
    with pytest.raises(ValueError, match="unknown reward targets"):
        make_settings(reward={"kind": "tracking", "targets": {"pose": 1.0}})
    with pytest.raises(ValueError, match="reward target 'height'"):
        make_settings(reward={"kind": "gait", "targets": {"height": float("nan")}})


def test_max_model_time_ends_an_episode_held_in_one_model():
    """``max_model_time_s``: the episode ends (``model_time``) in the first period after which
    the current model has lasted longer, by the contact clock; off by default."""
    teacher = controller_from("model:teacher_robust")
    ends = []
    for limit in (None, 0.3):
        env = gym.make("ConstrainedBiped-v0", termination={"max_model_time_s": limit})
        obs, _ = env.reset(seed=3)
        held = 0
        for _ in range(1000):
            obs, _, term, _, info = env.step(teacher(obs))
            held = held + 1 if info["switches"] == () else 0
            if term:
                break
        ends.append((term, info["termination_reason"], held, info["mode"]))
    assert ends[0][0] is False  # the teacher walks on without the limit
    term, reason, held, mode = ends[1]
    assert term and reason == "model_time" and mode in (1, 2)
    assert held * 0.005 == pytest.approx(0.3 + 0.005, abs=1e-9)  # 61 periods without a switch
    with pytest.raises(ValueError, match="max_model_time_s"):
        gym.make("ConstrainedBiped-v0", termination={"max_model_time_s": 0.0})
