"""ConstrainedBiped-v0: API conformance, determinism, bad input, info consistency, rendering."""

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import biped_constraint_env  # noqa: F401
from biped_constraint_env.env import ConstrainedBipedEnv
from biped_constraint_env.modes import Mode
from biped_constraint_env.observation import OBS_NAMES
from biped_constraint_env.rewards import REWARD_TERMS

ENV_ID = "ConstrainedBiped-v0"
V1 = {"task": "paper", "preset": "default"}  # the paper's task (rest, 20 ms), accurate physics
SMALL = 8.0  # [N m] random torques small enough that episodes last tens of steps


def _rollout(env, seed, n, scale=SMALL):
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, info)]
    for _ in range(n):
        obs, r, te, tr, info = env.step(rng.uniform(-scale, scale, 5).astype(np.float32))
        out.append((obs, r, info))
        if te or tr:
            obs, info = env.reset()
    return out


ACTION_SCALE_ADVICE = (
    "symmetric and normalized space",
    "symmetric and normalized Box action space",
)
"""The one expected checker message: the mission fixes the action in N m (STYLE.md); the
training scripts rescale it to [-1, 1]. Any other warning fails the tests below."""


def test_gymnasium_check_env_no_other_warnings():
    env = gym.make(ENV_ID, **V1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    others = [
        str(w.message) for w in caught if not any(a in str(w.message) for a in ACTION_SCALE_ADVICE)
    ]
    assert not others


def test_sb3_check_env():
    from stable_baselines3.common.env_checker import check_env as sb3_check

    env = ConstrainedBipedEnv(**V1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check(env, warn=True)
    others = [
        str(w.message) for w in caught if not any(a in str(w.message) for a in ACTION_SCALE_ADVICE)
    ]
    assert not others


def test_make_and_spaces():
    env = gym.make(ENV_ID, **V1)
    assert env.spec.max_episode_steps is None  # truncation by simulated time (time_limit_s)
    assert env.unwrapped.settings.time_limit_s == 30.0
    assert env.action_space.shape == (5,) and env.action_space.high[0] == 150.0
    obs, info = env.reset(seed=0)
    assert obs.shape == (24,) and len(OBS_NAMES) == 24
    assert info["mode"] == 1 and obs[17] == 1.0 and obs[16] == 0.0
    assert env.metadata["render_fps"] == 50


def test_determinism_same_seed():
    a = _rollout(gym.make(ENV_ID, **V1), 7, 150)
    b = _rollout(gym.make(ENV_ID, **V1), 7, 150)
    for (oa, ra, _), (ob, rb, _) in zip(a, b, strict=True):
        assert np.array_equal(oa, ob) and ra == rb


def test_obs_in_space_and_reward_equals_terms():
    env = gym.make(ENV_ID, **V1)
    for obs, r, info in _rollout(env, 3, 600):
        assert env.observation_space.contains(obs)
        assert r == pytest.approx(sum(info[k] for k in REWARD_TERMS), abs=1e-12)


def test_info_consistent_with_state():
    env = gym.make(ENV_ID, **V1)
    env.reset(seed=1)
    u = env.unwrapped
    y0 = u.keypoints()["hip"][0]
    obs, r, te, tr, info = env.step(np.zeros(5, np.float32))
    assert info["hip_y"] == pytest.approx(u.keypoints()["hip"][0])
    assert info["reward_forward"] == pytest.approx((info["hip_y"] - y0) / u.dt)
    assert info["mode"] == int(u.state.mode) and info["t"] == pytest.approx(u.state.t)
    assert obs[13] == pytest.approx(u.keypoints()["hip"][1])
    assert obs[:6] == pytest.approx(np.angle(np.exp(1j * u.state.q)))
    assert set(u.keypoints()) >= {"stance_toe", "swing_heel", "hip", "stance_knee", "swing_ankle"}


@pytest.mark.parametrize(
    "bad",
    [
        np.full(5, np.nan),
        np.full(5, np.inf),
        np.zeros(4),
        np.zeros((5, 1)),
        np.array(["a"] * 5),
        [1, 2, 3],
    ],
)
def test_bad_actions_raise(bad):
    env = gym.make(ENV_ID, **V1).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(bad)


def test_out_of_range_clip_or_raise():
    env = ConstrainedBipedEnv(**V1)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.full(5, 1e4))
    assert info["reward_ctrl"] == pytest.approx(-0.1 * 5)  # clipped to the limit
    env2 = ConstrainedBipedEnv(**V1, action={"out_of_range": "raise"})
    env2.reset(seed=0)
    with pytest.raises(ValueError, match="limit"):
        env2.step(np.full(5, 200.0))


@pytest.mark.parametrize("policy", ["clip", "raise"])
def test_compiled_torque_check_agrees_with_validate_actions(policy):
    """The env's compiled check refuses exactly what validate_actions refuses, clips the same."""
    from biped_constraint_env.actions import action_config, nb_check_torques, validate_actions

    rng = np.random.default_rng(3)
    acfg = action_config(150.0, policy)
    specials = [np.nan, np.inf, -np.inf, 150.0, -150.0, 150.0001, -1e9, 0.0]
    for _ in range(400):
        a = rng.uniform(-200, 200, 5)
        for j in np.flatnonzero(rng.random(5) < 0.2):
            a[j] = specials[rng.integers(len(specials))]
        act = a[None, :].copy()
        try:
            expected = validate_actions(a, 150.0, policy)
        except ValueError:
            expected = None
        refused = nb_check_torques(act, acfg)
        assert refused == (expected is None), a
        if expected is not None:
            assert np.array_equal(act[0], expected), a


def test_refused_action_leaves_the_state():
    env = ConstrainedBipedEnv(**V1, action={"out_of_range": "raise"})
    env.reset(seed=0)
    before = env.state
    for bad in (np.array([0, 0, np.nan, 0, 0]), np.full(5, 151.0)):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)
        after = env.state
        assert after.t == before.t and np.array_equal(after.q, before.q)
    env.step(np.zeros(5))  # still usable


def test_reset_options_and_impossible_state():
    env = ConstrainedBipedEnv(**V1)
    q = np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])
    obs, info = env.reset(options={"q": q, "qd": np.zeros(6), "mode": 1})
    assert obs[:6] == pytest.approx(q) and info["mode"] == 1
    with pytest.raises(ValueError, match="below the ground"):
        env.reset(options={"q": np.array([0.0, -1.4, 1.4, 0.0, 0.0, 0.0])})
    with pytest.raises(ValueError, match="theta0"):
        env.reset(options={"q": np.array([-0.1, -0.1, 0.1, -0.3, -0.4, 0.7]), "mode": 1})
    with pytest.raises(ValueError, match="swing_heel"):
        env.reset(options={"q": q, "mode": 3})
    with pytest.raises(ValueError, match="mode"):
        env.reset(options={"q": q, "mode": 7})
    with pytest.raises(ValueError, match="unknown"):
        env.reset(options={"q": q, "foo": 1})


def test_bad_constructor_arguments():
    with pytest.raises(ValueError, match="preset"):
        ConstrainedBipedEnv(preset="turbo")
    with pytest.raises(ValueError, match="dt"):
        ConstrainedBipedEnv(dt=-0.01)
    with pytest.raises(ValueError, match="torque_limit_nm"):
        ConstrainedBipedEnv(action={"torque_limit_nm": np.nan})
    with pytest.raises(ValueError, match="integrator"):
        ConstrainedBipedEnv(physics={"integrator": "verlet"})


def test_termination_reason_and_no_truncation_before_limit():
    env = gym.make(ENV_ID, **V1)
    env.reset(seed=0)
    for _ in range(200):
        _, _, te, tr, info = env.step(np.array([-150, 0, 0, 0, 0], np.float32))
        if te or tr:
            break
    assert te and not tr
    assert info["termination_reason"] == "stance_foot_tips_back"


def test_truncation_by_time_limit():
    env = gym.make(ENV_ID, **V1, max_episode_steps=3)
    env.reset(seed=0)
    out = [env.step(np.zeros(5, np.float32)) for _ in range(3)]
    assert not any(o[2] for o in out) and out[-1][3]


def test_paper_preset_options():
    env = ConstrainedBipedEnv(preset="paper")
    o = env.options
    assert (
        o.integrator,
        o.impact,
        o.locate_events,
        o.jdot,
        o.strict,
        o.heel_force_includes_foot_weight,
    ) == ("euler", "paper", False, "finite_difference", False, False)
    assert (
        ConstrainedBipedEnv(preset="paper", physics={"integrator": "rk4"}).options.integrator
        == "rk4"
    )


def test_pickle_roundtrip_gives_same_future():
    env = ConstrainedBipedEnv(**V1)
    env.reset(seed=5)
    env.step(np.ones(5) * 3)
    clone = pickle.loads(pickle.dumps(env))
    a = env.step(np.ones(5))[0]
    b = clone.step(np.ones(5))[0]
    assert np.array_equal(a, b)


def test_rgb_array_frames():
    env = gym.make(ENV_ID, **V1, render_mode="rgb_array")
    env.reset(seed=0)
    f0 = env.render()
    for _ in range(5):
        env.step(np.array([0, 0, 30, -20, 0], np.float32))
    f1 = env.render()
    assert f0.shape == (360, 480, 3) and f0.dtype == np.uint8
    assert np.any(f0 != f1)


def test_unwrapped_exposes_state():
    env = gym.make(ENV_ID, **V1)
    env.reset(seed=0)
    st = env.unwrapped.state
    assert st.mode == Mode.FOOT_FLAT and st.stance_side == 0 and st.q.shape == (6,)


def test_switch_and_alive_terms():
    """A period with the 1 -> 2 switch earns the switch bonus; a terminating one no alive bonus."""
    env = ConstrainedBipedEnv(**V1)
    env.reset(seed=0)
    _, _, te, _, info = env.step(np.array([60.0, 0, 0, 0, 0]))  # ankle torque lifts the heel
    assert info["switches"] and info["switches"][0][1:] == (1, 2)
    assert info["reward_switch"] == pytest.approx(1.0 * len(info["switches"]))
    assert info["reward_alive"] == (0.0 if te else 0.5)
    env.reset(seed=0)
    _, _, te, _, info = env.step(np.array([-150.0, 0, 0, 0, 0]))
    assert te and info["reward_alive"] == 0.0


def test_fall_termination_optional():
    env = ConstrainedBipedEnv(
        **V1, termination={"fall_hip_height_m": 2.99}
    )  # hip below in ~9 periods
    env.reset(seed=0)
    for _ in range(100):
        _, _, te, _, info = env.step(np.zeros(5))
        if te:
            break
    assert te and info["termination_reason"] == "fall"
    with pytest.raises(ValueError, match="fall_hip_height_m"):
        ConstrainedBipedEnv(termination={"fall_hip_height_m": np.nan})


def test_midstride_start():
    """The walking task starts in model 2 in the documented ranges; a bad ``start`` raises."""
    from biped_constraint_env.starts import (
        MIDSTRIDE_RATE_RANGE_RAD_S,
        MIDSTRIDE_THETA0_RANGE_RAD,
        check_start_state,
        midstride_start,
    )

    env = gym.make("ConstrainedBiped-v0")
    assert env.spec.max_episode_steps is None and env.unwrapped.settings.time_limit_s == 30.0
    u = env.unwrapped
    assert u.dt == 0.005 and u.options.stop_at_switch and u.settings.start.start == "midstride"
    rates = []
    for seed in range(20):
        obs, info = env.reset(seed=seed)
        st = u.state
        assert info["mode"] == 2 and st.mode == Mode.TOE_PIVOT
        lo, hi = MIDSTRIDE_THETA0_RANGE_RAD
        assert lo <= st.q[0] <= hi
        rates.append(st.qd[0])
        check_start_state(u.params, st)
        assert obs[OBS_NAMES.index("hip_vy")] > 0  # moving forward
    lo, hi = MIDSTRIDE_RATE_RANGE_RAD_S
    assert lo <= min(rates) < max(rates) <= hi
    q, qd = midstride_start(-1.0, -0.2)
    assert qd[0] == -1.0 and qd[3] == 1.0 and q[0] == -0.2
    with pytest.raises(ValueError, match="start"):
        ConstrainedBipedEnv(start="running")
    with pytest.raises(ValueError):
        midstride_start(-1.0, 0.1)


def test_stride_start_draws_the_swing_leg_along_its_swing():
    """``start="stride"``: model 2 as the mid-stride start, or model 1 on the flat foot, the swing
    thigh's direction, knee and forward rate drawn over their documented ranges, the swing foot
    level; single = batched."""
    from biped_constraint_env.kinematics import link_angles
    from biped_constraint_env.starts import (
        STRIDE_KNEE_RANGE_RAD,
        STRIDE_SWING_RANGE_RAD,
        STRIDE_SWING_RATE_RANGE_RAD_S,
        check_start_state,
        midstride_start,
    )

    env = ConstrainedBipedEnv(start={"kind": "stride", "reset_noise_scale": 0.0})
    swings, knees, rates, modes = [], [], [], set()
    for seed in range(200):
        _, info = env.reset(seed=seed)
        st = env.state
        modes.add(info["mode"])
        if info["mode"] == 1:  # the stance foot flat, the leg turning about the ankle
            assert st.q[0] == st.qd[0] == 0.0 and st.qd[1] < 0
        check_start_state(env.params, st)
        phi = link_angles(st.q)
        swings.append(phi[3] - 1.5 * np.pi)  # the swing thigh, hip -> knee, from straight down
        knees.append(st.q[4])
        rates.append(np.sum(st.qd[:4]))  # the swing thigh's absolute turning rate
        assert np.sin(phi[5]) == pytest.approx(0.0, abs=1e-12)  # the swing foot level
        assert np.sum(st.qd) == pytest.approx(0.0, abs=1e-12)  # and keeping its direction
    assert modes == {1, 2}
    for values, (lo, hi) in ((swings, STRIDE_SWING_RANGE_RAD), (knees, STRIDE_KNEE_RANGE_RAD),
                             (rates, STRIDE_SWING_RATE_RANGE_RAD_S)):  # fmt: skip
        assert lo - 1e-12 <= min(values) < lo + 0.2 * (hi - lo)
        assert hi - 0.2 * (hi - lo) < max(values) <= hi + 1e-12
    q, qd = midstride_start(-1.0, -0.2, swing=-0.3, knee=-0.6, swing_rate=0.0)
    np.testing.assert_array_equal((q, qd), midstride_start(-1.0, -0.2))
    venv = gym.make_vec("ConstrainedBiped-v0", 3, vectorization_mode="vector_entry_point",
                        start="stride")  # fmt: skip
    vobs, _ = venv.reset(seed=7)
    for i in range(3):
        np.testing.assert_array_equal(ConstrainedBipedEnv(start="stride").reset(seed=7 + i)[0],
                                      vobs[i])  # fmt: skip


def test_start_draws_equal_numpy_uniform():
    """The starts' cheaper uniform draws are numpy's ``Generator.uniform`` numbers exactly."""
    from biped_constraint_env.starts import _uniform

    a, b = np.random.default_rng(11), np.random.default_rng(11)
    for _ in range(2000):
        x, y = a.uniform(-1.1, -0.9), _uniform(b, -1.1, -0.9)
        assert x == y and type(x) is type(y)
        assert np.array_equal(a.uniform(-0.01, 0.01, size=5), _uniform(b, -0.01, 0.01, 5))


def test_the_track_task_is_the_from_scratch_recipes_settings():
    """``task="track"``: the tracking settings as one named task, each still overridable."""
    import gymnasium as gym

    s = gym.make("ConstrainedBiped-v0", task="track").unwrapped.settings
    assert s.reward.kind == "tracking" and s.start.reference_fraction == 0.5
    assert s.action.kind == "pd"
    assert s.action.around == "reference" and s.action.offset == ((0.2, 0, 0, 0, 0),) * 4
    assert s.observation.phase_obs and s.dt == 0.005
    narrower = gym.make("ConstrainedBiped-v0", task="track", action={"range": 0.5}).unwrapped
    assert narrower.settings.action.range == 0.5  # merged onto the task's PD mapping
    assert narrower.settings.action.around == "reference"
    plain = gym.make(
        "ConstrainedBiped-v0", task="track", start="midstride", action="torque"
    ).unwrapped
    assert plain.settings.start.reference_fraction == 0.0 and not plain.settings.action.pd
    walk = gym.make("ConstrainedBiped-v0").unwrapped
    assert walk.settings.reward.kind == "env" and not walk.settings.action.pd
    assert "reward=RewardSettings(kind='env'" in repr(walk)


@pytest.mark.parametrize("dt", [0.005])
def test_episodes_are_truncated_by_simulated_time_in_the_single_and_batched_env(dt):
    """A walk truncated at 30 s of simulated time, not after 6000 (or 1500) periods that end
    early at switches: the single env and every row of the batched env alike."""
    from training.controller.model_controller import controller_from

    kw = {"dt": dt, "termination": {"time_limit_s": 3.0}}
    env = gym.make(ENV_ID, **kw)
    ctl = controller_from("model:teacher_robust")
    obs, _ = env.reset(seed=0)
    ts = []
    while True:
        obs, _, term, trunc, info = env.step(ctl(obs))
        ts.append(info["t"])
        if term or trunc:
            break
    assert trunc and not term and 3.0 <= info["t"] < 3.0 + dt + 1e-9 and ts[-2] < 3.0
    from training.evaluation.evaluate import controller_batch

    venv = gym.make_vec(ENV_ID, 3, vectorization_mode="vector_entry_point", **kw)
    ctl = controller_batch("model:teacher_robust", 3)
    obs, _ = venv.reset(seed=0)
    for _ in range(len(ts)):
        obs, _, term, trunc, vinfo = venv.step(ctl(obs))
    assert trunc[0] and vinfo["t"][0] == info["t"]
