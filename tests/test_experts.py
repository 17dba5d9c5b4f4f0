"""A set of experts with the gate as data over named observation entries (training.ppo.experts)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from biped_constraint_env.observation import observation_names
from training.ppo.config import PPOConfig
from training.ppo.experts import check_experts, expert_rows

NAMES = observation_names(("phase", "command"))
STAND = {"name": "stand", "when": {"command_m_s": 0.0, "mode_4": 1.0}, "critic": "own"}
BRAKE = {"name": "brake", "when": {"command_m_s": 0.0}}


def _cfg(**kw) -> PPOConfig:
    cfg = PPOConfig(env={"task": "command"}, policy="experts", experts=(STAND, BRAKE), **kw)
    cfg.validate()
    return cfg


@pytest.mark.parametrize(
    "experts, match",
    [
        (({"name": "stand"},), "takes name, when"),
        (({"name": "stand", "when": {"command_m_s": 0.0}, "gate": 1},), "takes name, when"),
        (({"name": "walk", "when": {"command_m_s": 0.0}},), "new identifier"),
        ((BRAKE, BRAKE), "new identifier"),
        (({"name": "x", "when": {}},), "a table of observation entry"),
        (({"name": "x", "when": {"command": 0.0}},), "not an observation entry"),
        (({"name": "x", "when": {"mode_4": True}},), "must be a number"),
        (({"name": "x", "when": {"mode_4": 1.0}, "critic": "theirs"},), "critic must be"),
    ],
)
def test_a_wrong_expert_table_is_refused_naming_it(experts, match):
    with pytest.raises(ValueError, match=match):
        check_experts(experts, NAMES)


def test_the_policy_and_its_tables_go_together():
    with pytest.raises(ValueError, match="go together"):
        PPOConfig(env={"task": "command"}, policy="experts").validate()
    with pytest.raises(ValueError, match="go together"):
        PPOConfig(env={"task": "command"}, experts=(BRAKE,)).validate()
    with pytest.raises(ValueError, match="not an observation entry"):
        PPOConfig(policy="experts", experts=(BRAKE,)).validate()  # no command in "walk"
    with pytest.raises(ValueError, match="does not combine with stand_branch"):
        _cfg(stand_branch=True)


def test_the_first_table_that_matches_acts_and_walk_elsewhere():
    experts = check_experts((STAND, BRAKE), NAMES)
    obs = torch.zeros(4, len(NAMES))
    c, m4 = NAMES.index("command_m_s"), NAMES.index("mode_4")
    obs[0, c], obs[1, [c, m4]], obs[2, m4] = 1.0, torch.tensor([0.0, 1.0]), 0.0
    obs[3, c], obs[3, m4] = 0.5, 1.0
    # command 1: walk; command 0 in model 4: stand; command 0 elsewhere: brake; 0.5 in 4: walk
    assert expert_rows(obs, experts).tolist() == [0, 1, 2, 0]


def test_each_row_gets_its_experts_action_value_and_an_exact_ratio():
    from training.ppo.policy_io import build_policy

    torch.manual_seed(0)
    cfg = _cfg()
    policy = build_policy(cfg)
    for p in policy.parameters():  # away from the initial small heads: the experts differ
        p.data.normal_(0.0, 0.3)
    obs = torch.randn(6, len(NAMES))
    c, m4 = NAMES.index("command_m_s"), NAMES.index("mode_4")
    obs[:, c] = torch.tensor([1.0, 0.0, 0.0, 2.0, 0.0, 0.0])
    obs[:, m4] = torch.tensor([1.0, 1.0, 0.0, 0.0, 1.0, 0.0])
    which = policy.expert_rows(obs).tolist()
    assert which == [0, 1, 2, 0, 1, 2]
    with torch.no_grad():
        dist = policy.get_distribution(obs)
        feats = policy.extract_features(obs)
        walk = policy.action_net(policy.mlp_extractor.policy_net(feats))
        for i, k in enumerate(which):
            want = walk[i] if k == 0 else policy.heads[k - 1](policy.actors[k - 1](feats))[i]
            torch.testing.assert_close(dist.distribution.mean[i], want)
            std = policy.log_std if k == 0 else policy.log_stds[k - 1]
            torch.testing.assert_close(dist.distribution.stddev[i], std.exp())
        actions, values, log_prob = policy(obs)
        values2, log_prob2, _ = policy.evaluate_actions(obs, actions)
        torch.testing.assert_close(log_prob2, log_prob)  # PPO's ratio is exactly 1 at start
        torch.testing.assert_close(values2, values)
        shared = policy.value_net(policy.mlp_extractor.value_net(feats))
        own = policy.critics["stand"](feats)
        for i, k in enumerate(which):
            torch.testing.assert_close(values[i], own[i] if k == 1 else shared[i])


def test_the_gate_entries_are_read_as_the_env_gives_them():
    """The normaliser holds the command and the model one-hot's gate entry at the identity."""
    from training.ppo.build import training_env

    cfg = _cfg(n_envs=4)
    _, vecnorm = training_env(cfg, 3)
    try:
        pinned = cfg.pinned_entries()
        assert {NAMES.index("command_m_s"), NAMES.index("mode_4"), NAMES.index("hip_vy")} == \
            set(pinned)  # fmt: skip
        vecnorm.reset()
        for _ in range(20):
            obs, *_ = vecnorm.step(np.zeros((4, 5), np.float32))
        raw = vecnorm.get_original_obs()
        np.testing.assert_array_equal(obs[:, pinned], np.clip(raw[:, pinned], -10, 10))
        assert not np.allclose(vecnorm.obs_rms.mean, 0)  # the other entries are normalised
    finally:
        vecnorm.close()


def test_a_schedule_copies_an_actor_once_and_freezes_actors_from_its_step(tmp_path):
    from training.ppo.build import make_model, training_env
    from training.ppo.callbacks import actor_schedule
    from training.ppo.experts import actor_parameters

    entry = {"at": 10, "copy": {"brake": "walk"}, "frozen": ["walk"]}
    cfg = _cfg(n_envs=2, n_steps=8, batch_size=16, schedule=(entry,))
    _, vecnorm = training_env(cfg, 0)
    try:
        model = make_model(cfg, vecnorm, tmp_path)
        p = model.policy
        cb = actor_schedule(cfg, 0)
        cb.init_callback(model)
        cb.on_training_start({}, {})
        assert all(q.requires_grad for q in p.parameters())
        walk, brake = actor_parameters(p, "walk"), actor_parameters(p, "brake")
        assert not all(torch.equal(a, b) for a, b in zip(walk, brake, strict=True))
        model.num_timesteps = 10
        cb.on_rollout_start()
        assert all(torch.equal(a, b) for a, b in zip(walk, brake, strict=True))
        assert not any(q.requires_grad for q in walk) and all(q.requires_grad for q in brake)
        with torch.no_grad():
            brake[0].add_(1.0)  # learning on: a later rollout copies nothing again
        model.num_timesteps = 20
        cb.on_rollout_start()
        assert not torch.equal(walk[0], brake[0])
        resumed = actor_schedule(cfg, 1)  # a session that starts in the entry's phase
        resumed.init_callback(model)
        p.log_std.requires_grad_(True)
        resumed.on_training_start({}, {})
        assert not p.log_std.requires_grad and not torch.equal(walk[0], brake[0])  # no copy
    finally:
        vecnorm.close()
    for bad, match in (({"copy": {"brake": "nobody"}}, "copy must be"),
                       ({"frozen": ["stand", "x"]}, "frozen must be")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            _cfg(schedule=({"at": 5, **bad},))
    with pytest.raises(ValueError, match="need --policy experts"):
        PPOConfig(env={"task": "command"}, schedule=({"at": 5, "frozen": ["walk"]},)).validate()
