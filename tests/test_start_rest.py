"""The paper's scene: starts at rest in the Fig. 2 posture, the teacher's start phase, and the
evaluation command's start flag."""

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from training.controller.model_controller import TEACHER, at_rest, controller_from, state_from_obs

POLICY = Path(__file__).resolve().parents[1] / "policies" / "ppo_walker"


def test_mixed_start_draws_both_starts_the_same_in_both_envs():
    kw = {"start": "mixed"}
    single = gym.make("ConstrainedBiped-v0", **kw)
    modes = [single.reset(seed=s)[1]["mode"] for s in range(20)]
    assert set(modes) == {1, 2}  # at rest (model 1) and mid-stride (model 2)
    venv = gym.make_vec(
        "ConstrainedBiped-v0", num_envs=20, vectorization_mode="vector_entry_point", **kw
    )
    _, info = venv.reset(seed=0)
    assert list(info["mode"]) == modes


def test_start_mixture_draws_its_components_by_weight_the_same_in_both_envs():
    from biped_constraint_env.starts import midstride_start

    # "mixed" is the mixture {rest: 1/2, midstride: 1/2}: the same draws, start by start
    a = gym.make("ConstrainedBiped-v0", start="mixed")
    b = gym.make("ConstrainedBiped-v0", start={"rest": 1, "midstride": 1})
    for s in range(10):
        assert np.array_equal(a.reset(seed=s)[0], b.reset(seed=s)[0])
    kw = {"start": {"kind": {"stride": 0.75, "midstride": 0.25}, "reset_noise_scale": 0.0}}
    env = gym.make("ConstrainedBiped-v0", **kw)
    swing = midstride_start(-1.0, -0.2)[0][3]  # the mid-stride start's swing thigh
    picks = []
    for s in range(400):
        env.reset(seed=s)
        picks.append(env.unwrapped.state.q[3] == swing)  # the stride start draws the swing
    assert 0.18 < np.mean(picks) < 0.32  # 1/4 of the starts mid-stride (400 draws)
    venv = gym.make_vec(
        "ConstrainedBiped-v0", num_envs=16, vectorization_mode="vector_entry_point", **kw
    )
    obs, _ = venv.reset(seed=3)
    single = gym.make("ConstrainedBiped-v0", **kw)
    assert np.array_equal(obs[5], single.reset(seed=3 + 5)[0])
    assert env.unwrapped.settings.as_dict()["start"]["start"] == {"stride": 0.75, "midstride": 0.25}
    for bad, words in (({"strid": 1}, "did you mean 'stride'"), ({"rest": 0}, "positive weight"),
                       (5, "or a mixture")):  # fmt: skip
        with pytest.raises(ValueError, match=words):
            gym.make("ConstrainedBiped-v0", start=bad)


def test_rest_start_is_the_fig2_posture_at_rest():
    env = gym.make("ConstrainedBiped-v0", start="rest")
    obs, info = env.reset(seed=0)
    assert info["mode"] == 1 and at_rest(state_from_obs(obs))


def test_stand_start_is_an_exact_double_support_at_rest_in_both_envs():
    from biped_constraint_env.starts import (
        STAND_HIP_Y_RANGE_M,
        STAND_HIP_Z_RANGE_M,
        STAND_TOE_Y_RANGE_M,
        stand_start,
    )  # fmt: skip

    env = gym.make("ConstrainedBiped-v0", start="stand").unwrapped
    venv = gym.make_vec("ConstrainedBiped-v0", 4, vectorization_mode="vector_entry_point",
                        start="stand")  # fmt: skip
    vobs, _ = venv.reset(seed=3)
    for i in range(4):
        obs, info = env.reset(seed=3 + i)
        np.testing.assert_array_equal(obs, vobs[i])  # row i is the single env seeded 3 + i
        st, kp = env.state, env.keypoints()
        assert info["mode"] == 4 and not st.qd.any()
        assert kp["stance_toe"][1] == 0.0 and abs(kp["stance_heel"][1]) < 1e-12  # flat
        assert abs(kp["swing_toe"][1]) < 1e-12 < kp["swing_heel"][1]  # rear toe down, heel up
        assert STAND_TOE_Y_RANGE_M[0] <= kp["swing_toe"][0] <= STAND_TOE_Y_RANGE_M[1]
        assert STAND_HIP_Y_RANGE_M[0] <= kp["hip"][0] <= STAND_HIP_Y_RANGE_M[1]
        assert STAND_HIP_Z_RANGE_M[0] <= kp["hip"][1] <= STAND_HIP_Z_RANGE_M[1]
        assert kp["stance_knee"][0] > kp["stance_ankle"][0]  # knees bent forward
    q = stand_start(env.params, -0.6, 2.75, -1.0, 0.1)  # the construction is the stance asked
    env.reset(options={"q": q, "qd": np.zeros(6), "mode": 4})
    kp = env.keypoints()
    np.testing.assert_allclose(kp["hip"], [-0.6, 2.75], atol=1e-12)
    np.testing.assert_allclose(kp["swing_toe"], [-1.0, 0.0], atol=1e-12)


def test_brake_start_is_the_stand_moving_within_model_4_in_both_envs():
    """``start="brake"``: the standing start's postures with the hip moving forward at 0-0.8 m/s,
    the front foot flat and the rear toe still (model 4's constraints on the rates, exactly)."""
    from biped_constraint_env.kinematics import point_velocity
    from biped_constraint_env.model import SC_TOE5
    from biped_constraint_env.starts import BRAKE_HIP_SPEED_RANGE_M_S, stand_rates, stand_start

    env = gym.make("ConstrainedBiped-v0", start="brake").unwrapped
    venv = gym.make_vec("ConstrainedBiped-v0", 4, vectorization_mode="vector_entry_point",
                        start="brake")  # fmt: skip
    vobs, _ = venv.reset(seed=5)
    chain = env.params.chain(0)
    toe = float(chain.packed_scalars[SC_TOE5])
    speeds = []
    for i in range(4):
        obs, info = env.reset(seed=5 + i)
        np.testing.assert_array_equal(obs, vobs[i])
        st = env.state
        assert info["mode"] == 4 and st.q[0] == 0.0 and st.qd[0] == 0.0
        np.testing.assert_allclose(point_velocity(chain, st.q, st.qd, 5, toe), 0.0, atol=1e-12)
        hip_v = point_velocity(chain, st.q, st.qd, 3, 0.0)
        assert abs(hip_v[1]) < 1e-12 and abs(sum(st.qd)) < 1e-12  # level; the rear foot still
        assert BRAKE_HIP_SPEED_RANGE_M_S[0] <= hip_v[0] <= BRAKE_HIP_SPEED_RANGE_M_S[1]
        speeds.append(hip_v[0])
    assert len(set(speeds)) == 4 and max(speeds) > 0.0  # drawn per row
    q = stand_start(env.params, -0.6, 2.75, -1.0, 0.1)
    qd = stand_rates(env.params, q, 0.5)
    np.testing.assert_allclose(point_velocity(chain, q, qd, 3, 0.0), [0.5, 0.0], atol=1e-12)
    # a second route: the rates are the stance's own motion, the postures 0.1 ms either side
    h = 1e-4
    ahead, behind = (stand_start(env.params, -0.6 + s * 0.5 * h, 2.75, -1.0, 0.1) for s in (1, -1))
    np.testing.assert_allclose((ahead - behind) / (2 * h), qd, atol=1e-7)


def test_stride_stand_starts_are_exact_double_supports_in_a_walks_geometry_in_both_envs():
    """``start="stride_stand"`` / ``"stride_brake"`` / ``"stride_drift"``: the stand and brake
    starts drawn from the walk's double-support ranges (``STRIDE_STAND_*``), at rest / with the
    hip moving forward and down and the rear heel rising (``STRIDE_BRAKE_*``) / with the hip
    drifting level, mostly backward (``STRIDE_DRIFT_*``), model 4's constraints exact."""
    from biped_constraint_env.kinematics import point_velocity
    from biped_constraint_env.model import SC_TOE5
    from biped_constraint_env.starts import (
        BRAKE_HIP_SPEED_RANGE_M_S,
        STRIDE_BRAKE_HEEL_RATE_RANGE_RAD_S,
        STRIDE_BRAKE_HIP_VZ_RANGE_M_S,
        STRIDE_DRIFT_HIP_SPEED_RANGE_M_S,
        STRIDE_STAND_HEEL_UP_RANGE_RAD,
        STRIDE_STAND_HIP_Y_RANGE_M,
        STRIDE_STAND_HIP_Z_RANGE_M,
        STRIDE_STAND_TOE_Y_RANGE_M,
    )

    for start in ("stride_stand", "stride_brake", "stride_drift"):
        env = gym.make("ConstrainedBiped-v0", start=start).unwrapped
        venv = gym.make_vec("ConstrainedBiped-v0", 4, vectorization_mode="vector_entry_point",
                            start=start)  # fmt: skip
        vobs, _ = venv.reset(seed=11)
        chain = env.params.chain(0)
        toe = float(chain.packed_scalars[SC_TOE5])
        hips, rates = [], []
        for i in range(4):
            obs, info = env.reset(seed=11 + i)
            np.testing.assert_array_equal(obs, vobs[i])
            st, kp = env.state, env.keypoints()
            assert info["mode"] == 4 and st.q[0] == 0.0 and st.qd[0] == 0.0
            assert abs(kp["stance_heel"][1]) < 1e-12 and abs(kp["swing_toe"][1]) < 1e-12
            toe_lo, toe_hi = STRIDE_STAND_TOE_Y_RANGE_M
            assert toe_lo <= kp["swing_toe"][0] <= toe_hi
            assert STRIDE_STAND_HIP_Y_RANGE_M[0] <= kp["hip"][0] <= STRIDE_STAND_HIP_Y_RANGE_M[1]
            assert STRIDE_STAND_HIP_Z_RANGE_M[0] <= kp["hip"][1] <= STRIDE_STAND_HIP_Z_RANGE_M[1]
            heel_up = np.arcsin(
                (kp["swing_heel"][1] - kp["swing_toe"][1]) / chain.links[5].length_m
            )
            lo, hi = STRIDE_STAND_HEEL_UP_RANGE_RAD
            assert lo - 1e-9 <= heel_up <= hi + 1e-9
            np.testing.assert_allclose(point_velocity(chain, st.q, st.qd, 5, toe), 0.0, atol=1e-12)
            hip_v = point_velocity(chain, st.q, st.qd, 3, 0.0)
            if start == "stride_stand":
                assert not st.qd.any()
            elif start == "stride_drift":  # the hip level, the rear foot keeping its angle
                lo, hi = STRIDE_DRIFT_HIP_SPEED_RANGE_M_S
                assert lo <= hip_v[0] <= hi and abs(hip_v[1]) < 1e-12
                assert abs(sum(st.qd)) < 1e-12
                rates.append(hip_v[0])
            else:
                assert BRAKE_HIP_SPEED_RANGE_M_S[0] <= hip_v[0] <= BRAKE_HIP_SPEED_RANGE_M_S[1]
                assert STRIDE_BRAKE_HIP_VZ_RANGE_M_S[0] <= hip_v[1] <= 0.0
                heel_rate = -sum(st.qd)  # the rear foot's absolute rate, turning backward
                lo, hi = STRIDE_BRAKE_HEEL_RATE_RANGE_RAD_S
                assert lo <= heel_rate <= hi
                rates.append((hip_v[1], heel_rate))
            hips.append(kp["hip"][0])
        assert len(set(hips)) == 4 and len(set(rates)) == len(rates)  # drawn per row


def _first_step(ctl, env_kw, seed=0, limit_s=5.0):
    env = gym.make("ConstrainedBiped-v0", **env_kw)
    obs, info = env.reset(seed=seed)
    ctl.reset()
    phases = []
    while info["t"] < limit_s and info["steps_completed"] < 1:
        obs, _, term, _, info = env.step(ctl(obs))
        phases.append(ctl.starting_side)
        assert not term, info["termination_reason"]
    return info, phases


def test_nudge_start_is_the_rest_posture_turning_in_both_envs():
    """``start="nudge"``: model 1, the rest posture (with the reset noise), the stance leg
    turning about the ankle at a drawn rate in the range, forward or backward (rest inside the
    range), the swing thigh keeping its direction; single = batched."""
    from biped_constraint_env.starts import NOMINAL_POSTURE_RAD, NUDGE_RATE_RANGE_RAD_S

    env = gym.make("ConstrainedBiped-v0", start="nudge", dt=0.02).unwrapped
    venv = gym.make_vec("ConstrainedBiped-v0", 8, vectorization_mode="vector_entry_point",
                        start="nudge", dt=0.02)  # fmt: skip
    vo, _ = venv.reset(seed=11)
    lo, hi = NUDGE_RATE_RANGE_RAD_S
    assert lo < 0.0 < hi  # rest (rate 0) lies inside the range
    rates = []
    for i in range(8):
        o, info = env.reset(seed=11 + i)
        np.testing.assert_array_equal(o, vo[i])
        st = env.state
        assert info["mode"] == 1 and st.qd[0] == 0.0 and st.qd[1] == -st.qd[3]
        assert np.all(st.qd[[2, 4, 5]] == 0.0) and lo <= st.qd[1] <= hi
        np.testing.assert_allclose(st.q, NOMINAL_POSTURE_RAD, atol=0.0101)
        rates.append(st.qd[1])
    assert len(set(rates)) == 8 and min(rates) < -0.1
    more = [env.reset(seed=s)[0] for s in range(40)]  # backward ones too (hip moving back)
    assert min(o[14] for o in more) < 0.0 < max(o[14] for o in more)


def test_teacher_completes_its_first_step_from_rest_in_its_start_phase():
    ctl = controller_from(TEACHER)
    info, phases = _first_step(ctl, {"start": "rest"})
    assert info["steps_completed"] == 1 and info["stance_side"] == 1
    assert all(p == 0 for p in phases[:-1])  # the start phase, until the legs swap
    assert ctl.starting_side is None


def test_gait_alone_does_not_start_from_rest():
    ctl = controller_from("model:teacher_robust")  # no start phase
    env = gym.make("ConstrainedBiped-v0", start="rest")
    obs, info = env.reset(seed=0)
    for _ in range(2000):
        obs, _, term, _, info = env.step(ctl(obs))
        if term:
            break
    assert info["steps_completed"] == 0


def test_start_phase_stays_off_mid_stride():
    ctl = controller_from(TEACHER)
    _, phases = _first_step(ctl, {})
    assert all(p is None for p in phases)


def test_a_batch_call_refuses_a_stateful_controller():
    with pytest.raises(ValueError, match="start phase"):
        controller_from(TEACHER)(np.zeros((2, 24)))


def test_evaluate_takes_the_start(tmp_path):
    from training.evaluation import evaluate

    rc = evaluate.main([str(POLICY), "--episodes", "1", "--start", "rest", "--out", str(tmp_path)])
    assert rc == 0
    summary = json.loads((tmp_path / "evaluation.json").read_text())
    assert summary["start"] == "rest"
    (row,) = summary["results"]
    assert "rest start" in row["controller"] and "initiation" in row
    assert (tmp_path / "figures" / "rest_start_network.png").is_file()


SEED = 2  # start="mixed" draws rest, rest, mid-stride for seeds 2, 3, 4 (checked in the test)


def test_phase_observation_single_equals_batched_and_follows_the_clock():
    n, periods = 3, 400
    kw = {"start": "mixed", "observation": ["phase"]}
    venv = gym.make_vec(
        "ConstrainedBiped-v0", num_envs=n, vectorization_mode="vector_entry_point", **kw
    )
    assert venv.single_observation_space.shape == (26,)
    obs_b, _ = venv.reset(seed=SEED)
    singles = [gym.make("ConstrainedBiped-v0", **kw) for _ in range(n)]
    obs_s = np.array([e.reset(seed=SEED + i)[0] for i, e in enumerate(singles)])
    ctls = [controller_from(TEACHER) for _ in range(n)]
    np.testing.assert_array_equal(obs_b, obs_s)
    flags = [obs_s[:, 24].copy()]
    for _ in range(periods):
        acts = np.array([c(o) for c, o in zip(ctls, obs_s, strict=True)])
        obs_b, *_ = venv.step(acts)
        obs_s = np.array([e.step(a)[0] for e, a in zip(singles, acts, strict=True)])
        np.testing.assert_array_equal(obs_b, obs_s)
        flags.append(obs_s[:, 24].copy())
        assert np.all(obs_s[:, 25] >= 0)
    flags = np.array(flags)
    rest = [i for i in range(n) if flags[0, i] == 1]
    assert 0 < len(rest) < n, "the seeds of start='mixed' here include both starts"
    for i in rest:  # the flag ends with the first step (about 1.45 s in)
        assert flags[-1, i] == 0 and np.all(np.diff(flags[:, i]) <= 0)


def test_phase_clock_restarts_at_each_switch():
    env = gym.make("ConstrainedBiped-v0", start="rest", observation=["phase"])
    ctl = controller_from(TEACHER)
    obs, info = env.reset(seed=0)
    ctl.reset()
    assert obs[24] == 1.0 and obs[25] == 0.0
    mode = info["mode"]
    for _ in range(600):
        before = obs[25]
        obs, _, term, _, info = env.step(ctl(obs))
        assert not term
        if info["mode"] != mode:
            assert obs[25] == 0.0
        else:
            assert obs[25] == pytest.approx(min(before + 0.005, 2.0))
        mode = info["mode"]
        assert obs[24] == (info["steps_completed"] == 0)
