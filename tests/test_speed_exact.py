"""What makes training faster changes no number: a run as ``training.ppo.build`` makes it (Adam's
multi-tensor step, BatchVecNormalize, the batched env's few info keys, two numba threads)
trains bit for bit as Stable-Baselines3's defaults (one-tensor Adam, its VecNormalize, every
info key, one thread) on the same config and seed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import VecNormalize

from biped_constraint_env.vector_env import ConstrainedBipedVectorEnv
from training.plumbing.common import parse_config
from training.ppo import build, sb3_vec
from training.ppo.config import PPOConfig


class _Records(Logger):
    """A logger that keeps every record of every dump."""

    def __init__(self):
        super().__init__(folder=None, output_formats=[])
        self.dumps = []

    def dump(self, step=0):
        self.dumps.append(dict(self.name_to_value))
        super().dump(step)


def _train(fast: bool, cfg, tmp_path, steps, monkeypatch):
    """Weights, optimiser state, normaliser statistics and logger records after ``steps`` env
    steps, the run built as training builds it (``fast``) or with SB3's defaults."""
    torch.set_num_threads(1)  # the network's initialisation (a QR) depends on the threads
    with monkeypatch.context() as m:
        if not fast:
            m.setattr(sb3_vec, "BatchVecNormalize", VecNormalize)
            init = ConstrainedBipedVectorEnv.__init__
            m.setattr(ConstrainedBipedVectorEnv, "__init__",
                      lambda self, *a, info_keys=None, **kw: init(self, *a, **kw))  # fmt: skip
            m.setattr(build, "OPTIMIZER_KWARGS", None)  # SB3's default Adam
        venv, vecnorm = build.training_env(cfg, cfg.seed, env_threads=2 if fast else 1)
        model = build.make_model(cfg, vecnorm, tmp_path / str(fast))
        assert (type(vecnorm) is VecNormalize) != fast
        assert venv.venv.venv.info_keys == (sb3_vec.BatchedSB3VecEnv.INFO_KEYS if fast else None)
    foreach = model.policy.optimizer.param_groups[0]["foreach"]
    assert foreach is (True if fast else None)
    build.initial_actions(model, cfg)
    logger = _Records()
    model.set_logger(logger)
    model.learn(total_timesteps=steps)
    state = {k: v.detach().clone() for k, v in model.policy.state_dict().items()}
    optim = model.policy.optimizer.state_dict()["state"]
    stats = (vecnorm.obs_rms.mean.copy(), vecnorm.obs_rms.var.copy(), vecnorm.ret_rms.var.copy())
    venv.close()
    return state, optim, stats, logger.dumps


@pytest.mark.parametrize(
    "overrides",
    [
        {},
        # a time limit inside the rollouts (bootstrapped truncations), ReLU, a KL stop, clipped
        # values and an entropy bonus
        {"train_episode_s": 0.3, "activation": "relu", "target_kl": 0.002, "ent_coef": 0.01,
         "n_epochs": 3},
    ],
)  # fmt: skip
def test_the_fast_build_trains_bit_for_bit_as_sb3s_defaults(tmp_path, monkeypatch, overrides):
    cfg = parse_config(PPOConfig, ["--config", "training/configs/ppo_gait_50hz.toml"], "test")
    cfg = dataclasses.replace(cfg, n_envs=8, n_steps=32, batch_size=64, seed=3, **overrides)
    steps = 3 * cfg.n_envs * cfg.n_steps
    fast = _train(True, cfg, tmp_path, steps, monkeypatch)
    sb3 = _train(False, cfg, tmp_path, steps, monkeypatch)
    assert fast[0].keys() == sb3[0].keys()
    for k in fast[0]:
        assert torch.equal(fast[0][k], sb3[0][k]), k
    for a, b in zip(fast[1].values(), sb3[1].values(), strict=True):
        for k in a:
            assert torch.equal(a[k], b[k]), k
    for a, b in zip(fast[2], sb3[2], strict=True):
        np.testing.assert_array_equal(a, b)
    assert len(fast[3]) == len(sb3[3]) == 3
    for a, b in zip(fast[3], sb3[3], strict=True):
        a = {k: v for k, v in a.items() if not k.startswith("time/")}
        b = {k: v for k, v in b.items() if not k.startswith("time/")}
        assert a.keys() == b.keys()
        for k in a:
            assert np.array_equal(a[k], b[k]), (k, a[k], b[k])
