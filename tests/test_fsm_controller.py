"""The finite-state feedback controller, its action map and the PPO config's env settings."""

import json

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.env import OBS_NAMES, PRESETS, ConstrainedBipedEnv
from training import fsm_controller as F

COMMITTED = "training/controllers/fsm_cem.json"


def _random_states(n, seed=0):
    """Observations of valid states: env resets followed by random torques."""
    rng = np.random.default_rng(seed)
    env = ConstrainedBipedEnv(preset="fast")
    out = []
    obs, _ = env.reset(seed=seed)
    while len(out) < n:
        out.append((obs.copy(), env.unwrapped.keypoints()))
        obs, _, term, trunc, _ = env.step(rng.uniform(-30, 30, 5))
        if term or trunc:
            obs, _ = env.reset(seed=int(rng.integers(1 << 30)))
    return out


def test_world_angles_agree_with_keypoints():
    """The controller's swing-thigh and swing-foot angles, from obs, equal those of the FK."""
    states = _random_states(40)
    swing, foot, w3, w5 = F.swing_angles(np.array([o for o, _ in states]))
    for i, (_, kp) in enumerate(states):
        d3 = kp["swing_knee"] - kp["hip"]
        d5 = kp["swing_toe"] - kp["swing_heel"]
        assert abs(F._wrap(swing[i] - (np.arctan2(d3[1], d3[0]) + np.pi / 2))) < 1e-9
        assert abs(F._wrap(foot[i] - np.arctan2(d5[1], d5[0]))) < 1e-9


def test_torques_follow_the_pd_law_per_joint():
    obs = _random_states(1)[0][0][None, :]
    x = np.zeros(F.N_PARAMS)
    names = {n: i for i, n in enumerate(F.PARAM_NAMES)}
    x[names["kp_knee"]] = 50.0
    x[names["knee_behind_m1"]] = x[names["knee_ahead_m1"]] = -0.5
    tau = F.torques(x, obs)
    q4 = obs[0, OBS_NAMES.index("q4")]
    assert tau.shape == (1, 5)
    assert tau[0, 3] == pytest.approx(50.0 * (-0.5 - q4))
    assert np.all(tau[0, [0, 1, 2, 4]] == 0.0)
    # a different model row takes other targets
    obs2 = obs.copy()
    obs2[0, 17:21] = (0, 1, 0, 0)
    assert F.torques(x, obs2)[0, 3] == pytest.approx(50.0 * (0.0 - q4))
    # the limit clips
    x[names["kp_knee"]] = 1e6
    assert abs(F.torques(x, obs)[0, 3]) == 150.0


def test_save_load_roundtrip_and_errors(tmp_path):
    x = np.linspace(-1, 1, F.N_PARAMS)
    F.save(x, tmp_path / "c.json", "test")
    np.testing.assert_array_equal(F.load(tmp_path / "c.json"), x)
    with pytest.raises(ValueError):
        F.save(x[:-1], tmp_path / "bad.json")
    d = json.loads((tmp_path / "c.json").read_text())
    del d["params"]["kp_hip"]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match="kp_hip"):
        F.load(tmp_path / "bad.json")


def test_action_map_plain_and_residual():
    obs = _random_states(3)
    obs = np.array([o for o, _ in obs])
    a = np.array([[0.5, -2.0, 0.0, 1.0, -0.25]] * 3)
    plain = F.ActionMap(150.0)
    np.testing.assert_array_equal(plain(a, obs), np.clip(a, -1, 1) * 150.0)
    x = F.load(COMMITTED)
    res = F.ActionMap(150.0, x, 0.2)
    want = np.clip(F.torques(x, obs) + 30.0 * np.clip(a, -1, 1), -150, 150)
    np.testing.assert_allclose(res(a, obs), want)
    np.testing.assert_allclose(res(np.zeros_like(a), obs), F.torques(x, obs))
    with pytest.raises(ValueError):
        F.ActionMap(150.0, x, 0.0)
    with pytest.raises(ValueError):
        F.ActionMap(150.0, x[:3])


def test_committed_controller_documented_steps():
    """The committed controller completes the step count its file documents (seed 0, v0)."""
    x = F.load(COMMITTED)
    env = gym.make("ConstrainedBiped-v1", preset="fast")  # = v0, without its deprecation warning
    obs, _ = env.reset(seed=0)
    done = False
    while not done:
        obs, _, term, trunc, info = env.step(F.torques(x, obs)[0])
        done = term or trunc
    env.close()
    with open(COMMITTED) as fh:
        documented = json.load(fh)["measured"]["steps_by_reset_seed_0_9"]["fast"]
    assert info["steps_completed"] == documented[0]
    assert info["steps_completed"] >= 1


def test_ppo_config_reaches_the_env():
    """preset, fall height and the base controller in the PPO config act on the env it builds."""
    from training.sb3_vec import make_sb3_vec_env
    from training.train_ppo import PPOConfig

    cfg = PPOConfig(
        preset="paper", fall_hip_height_m=2.0, base_controller=COMMITTED, residual_scale=0.2
    )
    for vec in ("batched", "dummy"):
        venv = make_sb3_vec_env(2, 0, cfg.env_kwargs(), vec, cfg.env_id, cfg.action_map())
        inner = venv.venv._proto if vec == "batched" else venv.envs[0].unwrapped
        assert inner.options == PRESETS["paper"]
        assert inner.fall_hip_height_m == 2.0
        amap = venv.action_map if vec == "batched" else venv.envs[0].action_map
        assert amap.base is not None and amap.residual_scale == 0.2
        venv.close()


def test_train_ppo_residual_and_evaluate_smoke(tmp_path):
    """A residual run on the committed controller trains, saves and evaluates (tiny budget)."""
    from training import evaluate, train_ppo

    args = ["--config", "training/configs/ppo_residual.toml", "--out-dir", str(tmp_path)]
    args += ["--total-timesteps", "256", "--n-envs", "2", "--n-steps", "128", "--batch-size", "64"]
    args += ["--n-epochs", "1", "--eval-freq", "256", "--eval-episodes", "1", "--progress", "false"]
    assert train_ppo.main(args) == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    assert (
        'base_controller = "training/controllers/fsm_cem.json"' in (run / "config.toml").read_text()
    )
    assert evaluate.main([str(run), "--episodes", "1"]) == 0
    ep = json.loads((run / "evaluation.json").read_text())["episodes"][0]
    assert ep["steps_completed"] >= 0 and np.isfinite(ep["distance_m"])


def test_optimize_fsm_smoke(tmp_path):
    """The search runs a tiny budget and writes a loadable controller with its measured steps."""
    from training import optimize_fsm

    args = ["--out-dir", str(tmp_path), "--iterations", "2", "--population", "4"]
    assert optimize_fsm.main([*args, "--periods", "10", "--progress", "false"]) == 0
    (run,) = (tmp_path / "optimize_fsm").iterdir()
    x = F.load(run / "controller.json")
    with open(run / "controller.json") as fh:
        measured = json.load(fh)["measured"]["steps_by_reset_seed_0_9"]
    assert set(measured) == {"fast", "default"} and len(measured["fast"]) == 10
    assert x.shape == (F.N_PARAMS,)
