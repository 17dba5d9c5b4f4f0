"""The committed policy (policies/ppo_model_residual): it loads, and a short seeded episode is
deterministic and walks."""

from __future__ import annotations

from pathlib import Path

import numpy as np

POLICY = Path(__file__).resolve().parents[1] / "policies" / "ppo_model_residual"


def _episode(model, vecnorm, cfg, seed, periods):
    import gymnasium as gym

    env = gym.make(cfg.env_id, **cfg.env_kwargs())
    amap = cfg.action_map()
    obs, _ = env.reset(seed=seed)
    trace = [obs]
    for _ in range(periods):
        action, _ = model.predict(
            vecnorm.normalize_obs(obs[None].astype(np.float32)), deterministic=True
        )
        obs, _, term, trunc, info = env.step(amap(action, obs[None])[0])
        trace.append(obs)
        assert not (term or trunc)
    return np.array(trace), info


def test_committed_policy_loads_and_is_deterministic():
    import torch

    from training.evaluate import load

    torch.set_num_threads(1)
    model, vecnorm, cfg = load(POLICY, "final")
    assert cfg.env_id == "ConstrainedBiped-v0" and cfg.base_controller == "model"
    a, info = _episode(model, vecnorm, cfg, seed=0, periods=300)  # 1.5 s
    b, _ = _episode(model, vecnorm, cfg, seed=0, periods=300)
    np.testing.assert_array_equal(a, b)
    assert info["steps_completed"] >= 1, info
