"""Imitation (DART, DAgger, behaviour cloning), the per-joint gear, the push, the warm start."""

import gymnasium as gym
import numpy as np
import pytest
import torch

import biped_constraint_env  # noqa: F401
from training.controller.model_controller import ModelController
from training.ppo import imitation
from training.ppo.sb3_vec import ActionMap, make_sb3_vec_env

GEAR = np.array([60.0, 150.0, 150.0, 80.0, 65.0])


def _policy(mean, var):
    from stable_baselines3.common.policies import ActorCriticPolicy

    space = gym.spaces.Box(-np.inf, np.inf, (24,))
    return ActorCriticPolicy(
        space,
        gym.spaces.Box(-1, 1, (5,)),
        lambda _: 1e-3,
        net_arch=[32, 32],
        features_extractor_class=imitation.FixedNormalizer,
        features_extractor_kwargs={"mean": mean.tolist(), "var": var.tolist()},
    )


def test_collect_labels_are_the_teachers_and_noise_moves_the_state():
    env = gym.make("ConstrainedBiped-v0").unwrapped
    teacher = ModelController(params=env.params, options=env.options)
    clean = imitation.collect(env, teacher, GEAR, [5], 40)
    noisy = imitation.collect(env, teacher, GEAR, [5], 40, noise_nm=0.4)
    assert clean.steps == [0] and clean.ends == ["cap"] and len(clean.data) == 40
    # labels: the teacher's torque at each visited observation, in units of the gear
    for o, a in zip(clean.data.obs[:5], clean.data.act[:5], strict=True):
        np.testing.assert_allclose(a, np.clip(teacher(o) / GEAR, -1, 1), rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(clean.data.obs[0], noisy.data.obs[0])  # same start
    assert not np.array_equal(clean.data.obs[-1], noisy.data.obs[-1])  # DART noise acted


def test_fit_reduces_the_error_and_the_normaliser_lives_in_the_network():
    rng = np.random.default_rng(0)
    obs = rng.normal(3.0, 2.0, (2048, 24)).astype(np.float32)
    act = np.tanh(obs[:, :5] - 3.0).astype(np.float32) * 0.5
    data = imitation.Dataset(obs, act)
    mean, var = imitation.obs_statistics(obs)
    torch.manual_seed(0)
    pol = _policy(mean, var)
    before = imitation.fit(pol, data, 1, lr=0.0)
    after = imitation.fit(pol, data, 30, batch_size=128, lr=3e-3)
    assert after < 0.1 * before
    # the network alone maps raw observations: the student function needs no normaliser
    student = imitation.student_fn(pol)
    err = np.mean([(student(o) - a) ** 2 for o, a in zip(obs[:64], act[:64], strict=True)])
    assert err < 2 * after + 1e-3
    feats = pol.extract_features(torch.as_tensor(obs[:1]))
    np.testing.assert_allclose(
        feats.numpy()[0], np.clip((obs[0] - mean) / np.sqrt(var + 1e-8), -10, 10), rtol=1e-5
    )


def test_joint_weights_change_the_fit():
    rng = np.random.default_rng(1)
    obs = rng.normal(0, 1, (1024, 24)).astype(np.float32)
    act = np.sin(3 * obs[:, :5]).astype(np.float32) * 0.8
    data = imitation.Dataset(obs, act)
    mean, var = imitation.obs_statistics(obs)
    errs = []
    for w in (np.array([1.0, 1, 1, 1, 1]), np.array([20.0, 1, 1, 1, 1])):
        torch.manual_seed(0)
        pol = _policy(mean, var)
        imitation.fit(pol, data, 15, batch_size=128, lr=3e-3, weights=w)
        pred = np.array([imitation.student_fn(pol)(o) for o in obs[:256]])
        errs.append(np.mean((pred - act[:256]) ** 2, axis=0))
    assert errs[1][0] < errs[0][0]  # the weighted joint is fitted better


def test_gear_maps_actions_per_joint_and_rejects_bad_gear():
    amap = ActionMap(GEAR)
    a = np.array([[0.5, -1.0, 2.0, 0.0, -0.2]])
    np.testing.assert_allclose(amap(a, np.zeros((1, 24))), [[30.0, -150.0, 150.0, 0.0, -13.0]])
    for bad in ([0.0] * 5, [151.0] * 5, [np.nan] * 5):
        with pytest.raises(ValueError, match="gear"):
            ActionMap(bad)


def test_gear_same_in_the_batched_and_the_single_sb3_env():
    amap = ActionMap(GEAR)
    out = []
    for vec in ("batched", "dummy"):
        venv = make_sb3_vec_env(3, 7, {}, vec, action_map=amap)
        obs = [venv.reset()]
        rng = np.random.default_rng(0)
        for _ in range(40):
            o, r, d, _ = venv.step(rng.uniform(-0.05, 0.05, (3, 5)).astype(np.float32))
            obs.append(o)
        venv.close()
        out.append(np.array(obs, dtype=np.float32))  # the batched adapter returns float32
    np.testing.assert_array_equal(out[0], out[1])


def test_train_ppo_with_teacher_smoke(tmp_path):
    from training.ppo import train as train_ppo

    rc = train_ppo.main(
        ["--out-dir", str(tmp_path), "--teacher", "model", "--gear", *map(str, GEAR)]
        + ["--bc-episodes0", "2", "--bc-periods0", "60", "--bc-rounds", "1"]
        + ["--bc-episodes", "1", "--bc-periods", "30", "--bc-grad-steps", "20"]
        + ["--total-timesteps", "256", "--n-envs", "2", "--n-steps", "64", "--batch-size", "64"]
        + ["--eval-freq", "1000", "--checkpoint-freq", "1000", "--action-std-nm", "0.3"]
        + ["--critic-warmup", "1", "--bc-anchor-steps", "2", "--progress", "false"]
    )
    assert rc == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    assert (run / "imitation" / "policy.safetensors").is_file()
    assert (run / "imitation.csv").is_file()
    from training.ppo.policy_io import load_policy, load_state

    policy, _, cfg, state = load_policy(run, "final")
    assert isinstance(policy.features_extractor, imitation.FixedNormalizer)
    std = policy.log_std.exp().detach().numpy() * GEAR
    assert std == pytest.approx(np.full(5, 0.3), rel=0.2)  # action_std_nm, per joint in N m
    assert (run / "imitation" / "demos.npz").is_file()  # the anchor's data, for a resume
    assert state["num_timesteps"] >= 256
    rc = train_ppo.main(["--resume", str(run), "--total-timesteps", "384", "--progress", "false"])
    assert rc == 0
    assert load_state(run / "final")["num_timesteps"] >= 384
