"""The committed learned walker (policies/ppo_walker): the network alone loads, is deterministic
and walks."""

from __future__ import annotations

from pathlib import Path

import numpy as np

POLICY = Path(__file__).resolve().parents[1] / "policies" / "ppo_walker"


def test_committed_walker_is_a_network_alone_and_deterministic():
    import torch

    from training.evaluate import load, policy_actor, run_episodes
    from training.imitation import FixedNormalizer

    torch.set_num_threads(1)
    model, vecnorm, cfg = load(POLICY, "final")
    assert cfg.env_id == "ConstrainedBiped-v0" and cfg.base_controller == ""  # no controller
    assert cfg.env_kwargs()["task"] == "walk" and cfg.env_kwargs()["preset"] == "default"
    assert isinstance(model.policy.features_extractor, FixedNormalizer)
    assert not vecnorm.norm_obs  # the network normalises its own input
    actor = policy_actor(model, vecnorm, cfg)
    obs = np.zeros(24)
    obs[18] = 1.0
    np.testing.assert_array_equal(actor(obs), actor(obs))
    # one seeded evaluation episode (the README's seeds 0-9) walks at least 10 steps
    (ep,) = run_episodes(actor, cfg.env_kwargs(), [0], cfg.env_id)
    assert ep["steps_completed"] >= 10, ep
    assert ep["distance_m"] > 5.0
