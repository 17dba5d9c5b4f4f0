"""The first contact phase of a start near rest as a phase of its own (the sway before the
first step): the contact clock's ``opening`` flag, ``termination["max_first_phase_s"]`` and
the gait and command rewards' ``first_phase_s`` (single = batched: ``test_info_parity.py``)."""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.clock import ContactClock
from biped_constraint_env.command import CommandReward
from biped_constraint_env.gait import GaitReward
from biped_constraint_env.rewards import REWARD_KINDS, reward_settings
from biped_constraint_env.settings import make_settings
from training.controller.model_controller import controller_from

GAIT = {t.name: t for t in REWARD_KINDS["gait"]}
CADENCE = (0.6, 0.25, 0.15, 0.1)


def test_the_clock_opens_at_a_start_near_rest_and_closes_at_the_first_switch_for_good():
    clock = ContactClock(4, 0.02)
    qd = np.zeros((4, 6))
    qd[1, [1, 3]] = -0.6, 0.6  # the nudge start's fastest
    qd[3, 4] = 0.61  # one joint faster: not near rest
    clock.start(np.arange(4), np.array([1, 1, 2, 1]), qd)
    np.testing.assert_array_equal(clock.opening, [True, True, False, False])  # row 2: model 2
    clock.advance(np.array([1, 2, 2, 1]), np.zeros(4))  # row 1 switches
    np.testing.assert_array_equal(clock.opening, [True, False, False, False])
    clock.advance(np.array([1, 1, 2, 1]), np.zeros(4))  # back to model 1: not the first phase
    np.testing.assert_array_equal(clock.opening, [True, False, False, False])
    clock.advance(np.array([2, 1, 3, 1]), np.zeros(4), stepped=np.array([False, 1, 1, 1], bool))
    np.testing.assert_array_equal(clock.opening, [True, False, False, False])  # 0 not stepped
    clock.start(np.array([1]), np.array([1]), np.zeros((1, 6)))  # a new episode in row 1
    np.testing.assert_array_equal(clock.opening, [True, True, False, False])


def _gait(first_phase_s, kind="gait"):
    spec = {"kind": kind, "targets": {"cadence": list(CADENCE)}, "gated": True}
    if first_phase_s is not None:
        spec["first_phase_s"] = first_phase_s
    cls = GaitReward if kind == "gait" else CommandReward
    return cls(reward_settings(spec), 0.02, 4 if kind == "gait" else 2)


def test_the_first_phase_has_its_own_cadence_target_and_the_walk_keeps_the_models():
    """In the opening phase the cadence target is ``first_phase_s`` in any
    model; after it, each model's; without the setting, the flag changes nothing."""
    t_model = np.array([1.5, 1.5, 2.3, 0.4])
    first = np.array([True, False, True, True])
    modes = np.array([1, 1, 1, 3])
    args = (np.full(4, 0.02), np.full(4, 2.95), np.full(4, 1.0), modes, t_model, np.zeros(4),
            np.ones(4, bool))  # fmt: skip
    k, w = GAIT["cadence"].kernel, GAIT["cadence"].weight
    out = _gait(2.0).terms(*args, first_phase=first)
    over = np.array([0.0, 1.5 - 0.6, 2.3 - 2.0, 0.0])  # 0.4 s in model 3: within 2 s
    np.testing.assert_allclose(out[:, 3], w * np.exp(-k * over**2), rtol=1e-12)
    np.testing.assert_allclose(out[:, 0], GAIT["speed"].weight * np.exp(-k * over**2)
                               * np.exp(-GAIT["speed"].kernel * (1.0 - 1.1) ** 2))  # fmt: skip
    plain = _gait(None)
    np.testing.assert_array_equal(plain.terms(*args, first_phase=first), plain.terms(*args))
    np.testing.assert_array_equal(_gait(2.0).terms(*args, first_phase=np.zeros(4, bool)),
                                  plain.terms(*args))  # fmt: skip


def test_the_command_reward_takes_the_first_phase_target_too():
    t_model = np.array([1.5, 1.5])
    args = (np.full(2, 0.02), np.full(2, 2.95), np.full(2, 1.0), np.array([1, 1]), t_model,
            np.zeros(2), np.ones(2, bool), np.array([1.1, 1.1]))  # fmt: skip
    cadence = [t.name for t in REWARD_KINDS["command"]].index("cadence")
    kw = {"tau_sq": np.zeros(2), "first_phase": np.array([True, False])}
    on = _gait(2.0, "command").terms(*args, **kw)[:, cadence]
    off = _gait(None, "command").terms(*args, **kw)[:, cadence]
    assert on[0] > off[0] and on[1] == off[1] == off[0]


def test_first_phase_s_round_trips_and_is_refused_where_it_means_nothing():
    s = make_settings(reward={"kind": "gait", "first_phase_s": 2.0})
    assert s.reward.first_phase_s == 2.0
    assert make_settings(reward=s.reward.as_dict()).reward == s.reward
    assert "first_phase_s" not in make_settings(reward="gait").reward.as_dict()
    with pytest.raises(ValueError, match="'first_phase_s' is a setting of the 'gait' and"):
        make_settings(reward={"kind": "tracking", "first_phase_s": 2.0})
    with pytest.raises(ValueError, match="first_phase_s"):
        make_settings(reward={"kind": "gait", "first_phase_s": -1.0})
    with pytest.raises(ValueError, match="max_first_phase_s"):
        make_settings(termination={"max_first_phase_s": 0.0})
    t = make_settings(termination={"max_model_time_s": 1.0, "max_first_phase_s": 3.0})
    assert t.termination.as_dict()["max_first_phase_s"] == 3.0 and t.needs_clock


def _teacher_end(start, termination):
    """How the model teacher's episode from ``start`` ends under ``termination``: the reason,
    the model switches and the periods before the first."""
    teacher = controller_from("model:teacher_robust")
    env = gym.make("ConstrainedBiped-v0", start=start, termination=termination)
    obs, _ = env.reset(seed=3)
    switches, first_held = 0, 0
    for _ in range(1000):
        obs, _, term, _, info = env.step(teacher(obs))
        switches += len(info["switches"])
        first_held += switches == 0
        if term:
            break
    return info["termination_reason"], switches, first_held


def test_max_first_phase_s_limits_the_opening_phase_and_max_model_time_s_the_others():
    """From rest the teacher holds its first contact phase 1.09 s and ends by an event
    (``swing_foot_touchdown``): ``max_model_time_s=0.3`` ends it at 0.3 s (``model_time``);
    with ``max_first_phase_s`` the first phase has that limit instead (``first_phase_time``
    in the first period after it has lasted longer, 5 ms periods; none when long). A
    mid-stride start (model 2) is not near rest: its first phase keeps the model-time limit."""
    assert _teacher_end("rest", {}) == ("swing_foot_touchdown", 0, 219)
    assert _teacher_end("rest", {"max_model_time_s": 0.3}) == ("model_time", 0, 61)
    long = {"max_model_time_s": 0.3, "max_first_phase_s": 100.0}
    assert _teacher_end("rest", long) == ("swing_foot_touchdown", 0, 219)
    short = {"max_model_time_s": 0.3, "max_first_phase_s": 0.01}
    assert _teacher_end("rest", short) == ("first_phase_time", 0, 3)
    assert _teacher_end("rest", {"max_first_phase_s": 0.2}) == ("first_phase_time", 0, 41)
    assert _teacher_end("midstride", long) == _teacher_end("midstride", {"max_model_time_s": 0.3})
    assert _teacher_end("midstride", long) == ("model_time", 0, 61)
