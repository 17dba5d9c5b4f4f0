"""The training option ``stand_std_nm``: a fixed exploration noise on the rows told to stand."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from gymnasium import spaces

from training.ppo.config import PPOConfig
from training.ppo.exploration import HIP_VY, PinnedStats, StandNoisePolicy

COMMAND = {"env": {"task": "command", "action": "torque"}}


def _policy(stand_nm=0.5, log_std=-3.0, speed=0.0):
    obs = spaces.Box(-np.inf, np.inf, (27,), np.float32)
    act = spaces.Box(-1.0, 1.0, (5,), np.float32)
    stand = np.log(np.full(5, stand_nm / 150.0)).tolist()
    torch.manual_seed(0)
    return StandNoisePolicy(obs, act, lambda _: 1e-3, net_arch=[16, 16], log_std_init=log_std,
                            stand_log_std=stand, stand_speed=speed)  # fmt: skip


def test_rows_commanded_to_stand_get_the_fixed_noise_and_the_others_the_learned_one():
    policy = _policy()
    obs = torch.randn(6, 27)
    obs[:, -1] = torch.tensor([0.0, 0.3, 0.0, 2.0, 1e-6, 0.0])
    dist = policy.get_distribution(obs).distribution
    std = dist.stddev.detach().numpy()
    stand = np.array([True, False, True, False, False, True])
    assert std[stand] == pytest.approx(np.full((3, 5), 0.5 / 150.0), rel=1e-5)
    assert std[~stand] == pytest.approx(np.full((3, 5), np.exp(-3.0)), rel=1e-5)
    # the mean is the network's, whatever the noise
    assert torch.allclose(dist.mean, policy.action_net(policy.mlp_extractor.forward_actor(obs)))


def test_with_a_speed_gate_only_slow_rows_commanded_to_stand_get_the_fixed_noise():
    policy = _policy(speed=0.2)
    obs = torch.randn(5, 27)
    obs[:, -1] = torch.tensor([0.0, 0.0, 0.0, 1.0, 0.0])
    obs[:, HIP_VY] = torch.tensor([0.1, -0.15, 0.8, 0.0, -0.3])
    std = policy.get_distribution(obs).distribution.stddev.detach().numpy()[:, 0]
    small = np.isclose(std, 0.5 / 150.0, rtol=1e-5)
    assert small.tolist() == [True, True, False, False, False]
    assert np.allclose(std[~small], np.exp(-3.0), rtol=1e-5)


def test_rollout_and_update_compute_the_same_log_probability():
    """PPO's ratio is exactly 1 before any update: the same noise in both passes."""
    policy = _policy()
    obs = torch.randn(64, 27)
    obs[::3, -1] = 0.0
    with torch.no_grad():
        actions, _, logp = policy(obs)
        _, logp2, entropy = policy.evaluate_actions(obs, actions)
    assert torch.allclose(logp, logp2, atol=1e-5)
    # the standing rows' tiny noise gives them far higher log-densities and lower entropy
    d = policy.get_distribution(obs)
    assert d.distribution.stddev[0].max() < d.distribution.stddev[1].min()
    assert entropy.shape == (64,)


def test_the_learned_std_gets_no_gradient_from_standing_rows():
    policy = _policy()
    obs = torch.randn(8, 27)
    obs[:, -1] = 0.0
    _, logp, _ = policy.evaluate_actions(obs, torch.zeros(8, 5))
    logp.sum().backward()
    assert policy.log_std.grad is None or torch.all(policy.log_std.grad == 0)
    obs[:, -1] = 1.0
    policy.zero_grad()
    _, logp, _ = policy.evaluate_actions(obs, torch.zeros(8, 5))
    logp.sum().backward()
    assert torch.all(policy.log_std.grad != 0)


def test_its_weights_are_an_mlp_policys():
    """The stand noise is a setting, not a weight: the published network is a plain MlpPolicy."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    policy = _policy()
    plain = ActorCriticPolicy(policy.observation_space, policy.action_space, lambda _: 1e-3,
                              net_arch=[16, 16])  # fmt: skip
    assert {k: v.shape for k, v in policy.state_dict().items()} == {
        k: v.shape for k, v in plain.state_dict().items()
    }


def test_pinned_statistics_hold_the_command_entry_at_the_identity():
    stats = PinnedStats((4,), [-1])
    rng = np.random.default_rng(0)
    for _ in range(3):
        stats.update(rng.normal(3.0, 2.0, (50, 4)))
        assert stats.mean[-1] == 0.0 and stats.var[-1] == 1.0
        assert np.all(np.abs(stats.mean[:3] - 3.0) < 1.0) and np.all(stats.var[:3] > 1.0)
    frozen = PinnedStats((4,), [-1], frozen=True)
    frozen.mean, frozen.var = np.ones(4), np.full(4, 2.0)
    frozen.update(rng.normal(3.0, 2.0, (50, 4)))
    assert frozen.mean.tolist() == [1, 1, 1, 0] and frozen.var.tolist() == [2, 2, 2, 1]
    saved = np.array([1.0, 2.0, 3.0, 4.0])
    stats.mean, stats.var = saved, saved  # a restored snapshot
    assert stats.mean.tolist() == [1.0, 2.0, 3.0, 0.0] and stats.var.tolist() == [1, 2, 3, 1]
    assert saved[-1] == 4.0  # the caller's array untouched


@pytest.mark.parametrize(
    "extra, match",
    [
        ({"env": {"task": "walk"}}, "command as the observation's last entry"),
        ({"env": {"task": "command", "action": "pd"}}, "torque"),
        ({**COMMAND, "use_sde": True}, "use_sde"),
        ({**COMMAND, "target_kl": 0.02}, "target_kl"),
        ({**COMMAND, "train_env": {"task": "walk"}}, "command as the observation's last entry"),
    ],
)
def test_the_option_is_refused_where_it_means_nothing(extra, match):
    cfg = PPOConfig(stand_std_nm=0.5, **extra)
    with pytest.raises(ValueError, match=match):
        cfg.validate()
    PPOConfig(stand_std_nm=0.5, **COMMAND).validate()
    with pytest.raises(ValueError, match="at least 1e-3"):
        PPOConfig(stand_std_nm=1e-6, **COMMAND).validate()
    for alone in ({"stand_speed_m_s": 0.2}, {"stand_balance": True}):
        with pytest.raises(ValueError, match="go with --stand-std-nm"):
            PPOConfig(**alone, **COMMAND).validate()


def test_a_run_feeds_the_command_in_m_s_saves_an_mlp_policy_and_refuses_a_normalised_start(
    tmp_path,
):
    from training.ppo import train as train_ppo
    from training.ppo.policy_io import load_policy, read_normalizer

    flags = ["--total-timesteps", "128", "--n-envs", "2", "--n-steps", "32", "--batch-size",
             "64", "--n-epochs", "1", "--eval-freq", "1000", "--checkpoint-freq", "64",
             "--progress", "false", "--stand-std-nm", "0.5", "--env", "task=command"]  # fmt: skip
    assert train_ppo.main([*flags, "--out-dir", str(tmp_path / "a")]) == 0
    (run,) = (tmp_path / "a" / "train_ppo").iterdir()
    d = read_normalizer(run / "final" / "normalizer.npz")
    pinned = np.flatnonzero((d["obs_mean"] == 0.0) & (d["obs_var"] == 1.0))
    assert pinned.tolist() == [HIP_VY, 26]  # the hip speed and the command in m/s; the rest
    # normalised as ever
    policy, norm, cfg, _ = load_policy(run, "final")  # a plain MlpPolicy, loaded as any
    assert cfg.stand_std_nm == 0.5 and type(policy).__name__ == "ActorCriticPolicy"
    obs = np.zeros((1, 27), np.float32)
    obs[0, -1] = 1.25
    assert norm(obs)[0, -1] == pytest.approx(1.25)
    # a second stage from it starts from its network as it is
    rc = train_ppo.main([*flags, "--out-dir", str(tmp_path / "b"), "--init-from", str(run)])
    assert rc == 0
    (run_b,) = (tmp_path / "b" / "train_ppo").iterdir()
    assert json.loads((run_b / "init_from.json").read_text())["policy"] == str(run)
    # a run without the option would let those inputs drift from m/s: refused
    plain = [f for f in flags if f not in ("--stand-std-nm", "0.5")]
    with pytest.raises(SystemExit, match="give one of them to this run too"):
        train_ppo.main([*plain, "--out-dir", str(tmp_path / "p"), "--init-from", str(run)])


def test_a_start_that_read_the_command_normalised_is_folded_exactly_or_refused(tmp_path):
    """From a network trained without the option: the same actions from the same raw input."""
    import shutil

    from training.ppo import train as train_ppo
    from training.ppo.policy_io import (
        load_policy,
        policy_batch_actor,
        published_snapshot,
        write_manifest,
    )

    src = Path(__file__).resolve().parents[1] / "policies" / "ppo_command_stage1_50hz"
    flags = ["--config", str(src / "config.toml"), "--total-timesteps", "64", "--n-envs", "2",
             "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1", "--eval-freq", "1000",
             "--checkpoint-freq", "64", "--progress", "false", "--learning-rate", "1e-12",
             "--stand-std-nm", "0.5"]  # fmt: skip
    assert train_ppo.main([*flags, "--out-dir", str(tmp_path / "a"), "--init-from", str(src)]) == 0
    (run,) = (tmp_path / "a" / "train_ppo").iterdir()
    new, new_norm, cfg, _ = load_policy(run, "final")
    old, old_norm, _, _ = load_policy(src)
    for i in (HIP_VY, -1):
        assert new_norm.mean[i] == 0.0 and new_norm.var[i] == 1.0
        assert old_norm.var[i] > 0.1  # it did read them normalised
    rng = np.random.default_rng(0)
    obs = rng.normal(0.0, 1.0, (64, 27)).astype(np.float32) * np.sqrt(old_norm.var) + old_norm.mean
    obs[:, -1] = rng.uniform(0.0, 2.0, 64)
    obs[:, HIP_VY] = rng.uniform(-7.9, 7.9, 64)  # within the bound the fold passes unclipped
    obs[::4, -1] = 0.0
    a_new = policy_batch_actor(new, new_norm, cfg)(obs)
    a_old = policy_batch_actor(old, old_norm, cfg)(obs)
    assert np.abs(a_new - a_old).max() < 1e-3  # N m, of torques up to 150 (float32 and lr 1e-12)
    # a start whose normaliser clipped commands cannot be folded: refused
    bad = tmp_path / "clipped"
    shutil.copytree(src, bad)
    which, _ = published_snapshot(bad)
    npz = bad / which / "normalizer.npz"
    data = dict(np.load(npz))
    data["obs_var"] = data["obs_var"].copy()
    data["obs_var"][-1] = 0.01  # (5 m/s - mean) / 0.1 beyond the clip at 10
    np.savez(npz, **data)
    write_manifest(bad / which)  # a consistent snapshot, of a network that cannot be folded
    with pytest.raises(SystemExit, match="clipped below 5.0"):
        train_ppo.main([*flags, "--out-dir", str(tmp_path / "c"), "--init-from", str(bad)])
    # with a fresh normaliser nothing is kept exactly: folded all the same, up to the clip
    fresh = [*flags, "--out-dir", str(tmp_path / "d"), "--init-from", str(bad),
             "--init-normalizer", "fresh"]  # fmt: skip
    assert train_ppo.main(fresh) == 0
    (run,) = (tmp_path / "d" / "train_ppo").iterdir()
    new, new_norm, cfg, _ = load_policy(run, "final")
    old, old_norm, _, _ = load_policy(bad)
    assert new_norm.mean[-1] == 0.0 and new_norm.var[-1] == 1.0
    assert new_norm.var[0] != old_norm.var[0]  # the other entries' statistics start anew
    for net in ("policy_net", "value_net"):  # the command's column: divided by its old scale
        w_new, w_old = (getattr(p.mlp_extractor, net)[0].weight.detach().numpy()[:, -1]
                        for p in (new, old))  # fmt: skip
        np.testing.assert_allclose(w_new, w_old / np.sqrt(old_norm.var[-1] + 1e-8), rtol=1e-4)


def test_the_balance_scales_only_the_standing_rows_advantages_by_their_noise_ratio():
    from types import SimpleNamespace

    from training.ppo.exploration import stand_balance_callback

    policy = _policy(speed=0.2)  # stand noise 0.5 N m, learned exp(-3) x 150 = 7.5 N m
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(4, 3, 27)).astype(np.float32)
    obs[..., -1] = 1.0
    obs[0, :, -1] = 0.0  # commanded to stand ...
    obs[0, :, HIP_VY] = [0.1, 0.5, -0.05]  # ... and slow in two of three rows
    adv = rng.normal(size=(4, 3)).astype(np.float32)
    buf = SimpleNamespace(observations=obs, advantages=adv.copy())
    cb = stand_balance_callback()
    logged = {}
    logger = SimpleNamespace(record=lambda k, v: logged.update({k: v}))
    model = SimpleNamespace(policy=policy, rollout_buffer=buf, logger=logger,
                            normalize_advantage=False)  # fmt: skip
    cb.init_callback(model)
    cb.on_rollout_end()
    scale = (0.5 / 150.0) / np.exp(-3.0)
    want = (adv - adv.mean()) / (adv.std() + 1e-8)  # normalised over the rollout, then scaled
    want[0, [0, 2]] *= scale
    assert buf.advantages == pytest.approx(want, rel=1e-5)
    assert logged == pytest.approx(
        {"train/stand_rows": 2 / 12, "train/stand_advantage_scale": scale}
    )
