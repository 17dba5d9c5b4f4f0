"""LeanPPO over BatchVecNormalize computes what Stable-Baselines3's PPO over its VecNormalize
computes, bit for bit (training/ppo/lean.py, training/ppo/sb3_vec.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import VecNormalize

from training.plumbing.common import parse_config
from training.ppo import build, lean, sb3_vec
from training.ppo.config import PPOConfig
from training.ppo.lean import LeanPPO, lean_applies


class _Records(Logger):
    """A logger that keeps every record of every dump."""

    def __init__(self):
        super().__init__(folder=None, output_formats=[])
        self.dumps = []

    def dump(self, step=0):
        self.dumps.append(dict(self.name_to_value))
        super().dump(step)


def _train(cls, normalize, cfg, tmp_path, steps):
    """Weights, normaliser statistics and logger records of ``steps`` env steps of ``cls``
    over the normaliser ``normalize``, built as a run builds them."""
    torch.set_num_threads(1)
    saved = lean.LeanPPO, sb3_vec.BatchVecNormalize
    lean.LeanPPO, sb3_vec.BatchVecNormalize = cls, normalize
    try:
        venv, vecnorm = build.training_env(cfg, cfg.seed)
        model = build.make_model(cfg, vecnorm, tmp_path / cls.__name__)
    finally:
        lean.LeanPPO, sb3_vec.BatchVecNormalize = saved
    assert type(model) is cls and type(vecnorm) is normalize
    build.initial_actions(model, cfg)
    logger = _Records()
    model.set_logger(logger)
    model.learn(total_timesteps=steps)
    state = {k: v.detach().clone() for k, v in model.policy.state_dict().items()}
    optim = model.policy.optimizer.state_dict()["state"]
    stats = (vecnorm.obs_rms.mean.copy(), vecnorm.obs_rms.var.copy(), vecnorm.ret_rms.var.copy())
    venv.close()
    return state, optim, stats, logger.dumps, model


@pytest.mark.parametrize(
    "config, overrides",
    [
        ("training/configs/ppo_gait_50hz.toml", {}),
        # a time limit inside the rollouts (bootstrapped truncations), ReLU, a KL stop, clipped
        # values and an entropy bonus: the branches of SB3's rollout and update
        ("training/configs/ppo_gait_50hz.toml",
         {"train_episode_s": 0.3, "activation": "relu", "target_kl": 0.002,
          "ent_coef": 0.01, "n_epochs": 3}),
    ],
)  # fmt: skip
def test_lean_ppo_trains_bit_for_bit_as_sb3s_ppo(tmp_path, config, overrides):
    cfg = parse_config(PPOConfig, ["--config", config], "test")
    cfg = dataclasses.replace(cfg, n_envs=8, n_steps=32, batch_size=64, seed=3, **overrides)
    steps = 3 * cfg.n_envs * cfg.n_steps
    ours = _train(LeanPPO, sb3_vec.BatchVecNormalize, cfg, tmp_path, steps)
    sb3 = _train(PPO, VecNormalize, cfg, tmp_path, steps)
    assert lean_applies(ours[4].policy, ours[4].rollout_buffer)
    assert ours[0].keys() == sb3[0].keys()
    for k in ours[0]:
        assert torch.equal(ours[0][k], sb3[0][k]), k
    for (a, b) in zip(ours[1].values(), sb3[1].values(), strict=True):
        for k in a:
            assert torch.equal(a[k], b[k]), k
    for a, b in zip(ours[2], sb3[2], strict=True):
        np.testing.assert_array_equal(a, b)
    assert len(ours[3]) == len(sb3[3]) == 3
    for a, b in zip(ours[3], sb3[3], strict=True):
        a = {k: v for k, v in a.items() if not k.startswith("time/")}
        b = {k: v for k, v in b.items() if not k.startswith("time/")}
        assert a.keys() == b.keys()
        for k in a:
            assert np.array_equal(a[k], b[k]), (k, a[k], b[k])
    # a run that took a truncation's bootstrap: the second case's 0.3 s episodes
    if overrides:
        assert any(b.get("train/approx_kl", 0) > 0 for b in sb3[3])


def test_other_policies_run_sb3s_own_code(tmp_path):
    from torch import nn

    cfg = parse_config(PPOConfig, ["--config", "training/configs/ppo_gait_50hz.toml"], "test")
    cfg = dataclasses.replace(cfg, n_envs=4, n_steps=16, batch_size=32)
    venv, vecnorm = build.training_env(cfg, 0)
    model = build.make_model(cfg, vecnorm, tmp_path)
    assert lean_applies(model.policy, model.rollout_buffer)
    model.policy.mlp_extractor.policy_net.append(nn.Identity())
    assert not lean_applies(model.policy)
    model.learn(total_timesteps=64)  # SB3's path
    venv.close()
