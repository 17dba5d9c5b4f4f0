"""The committed learned walker (policies/ppo_walker): the network alone loads without
unpickling anything, is deterministic and walks."""

from __future__ import annotations

import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

POLICY = Path(__file__).resolve().parents[1] / "policies" / "ppo_walker"


class _Payload:
    """Unpickling this runs code: it writes a marker file."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (Path.write_text, (self.marker, "pwned"))


def test_committed_walker_is_a_network_alone_and_deterministic():
    import torch

    from training.plumbing.rollouts import run_episodes
    from training.ppo.imitation import FixedNormalizer
    from training.ppo.policy_io import load_policy, policy_actor

    torch.set_num_threads(1)
    policy, norm, cfg, state = load_policy(POLICY, "final")
    assert cfg.env_id == "ConstrainedBiped-v0" and cfg.base_controller == ""  # no controller
    settings = cfg.settings()
    assert settings.task == "walk" and settings.physics.preset == "default"
    assert isinstance(policy.features_extractor, FixedNormalizer)
    assert not norm.enabled  # the network normalises its own input
    assert state["num_timesteps"] > 0
    assert settings.start.start == "mixed" and settings.observation.phase_obs  # both starts
    actor = policy_actor(policy, norm, cfg)
    obs = np.zeros(cfg.obs_dim())
    obs[18] = 1.0
    np.testing.assert_array_equal(actor(obs), actor(obs))
    # one seeded evaluation episode (the README's seeds 0-9) from each start walks >= 10 steps
    for start in ("midstride", "rest"):
        (ep,) = run_episodes(actor, {**cfg.env_kwargs(), "start": start}, [0], cfg.env_id)
        assert ep["steps_completed"] >= 10, (start, ep)
        assert ep["distance_m"] > 5.0


def test_loading_a_policy_never_unpickles(monkeypatch, tmp_path):
    """A planted pickle payload in a policy directory is never run, and no loader unpickles."""
    from training.ppo.policy_io import load_policy

    run = tmp_path / "downloaded_policy"
    shutil.copytree(POLICY, run, ignore=shutil.ignore_patterns("figures"))
    marker = tmp_path / "marker"
    for name in ("vecnormalize.pkl", "final/vecnormalize.pkl", "model.zip"):
        (run / name).write_bytes(pickle.dumps(_Payload(marker)))

    def refuse(*_a, **_k):
        raise AssertionError("a policy loader unpickled")

    monkeypatch.setattr(pickle, "load", refuse)
    monkeypatch.setattr(pickle, "loads", refuse)
    monkeypatch.setattr(pickle, "Unpickler", refuse)
    for which in ("final", "imitation"):
        load_policy(run, which)
    assert not marker.exists()


def test_a_truncated_snapshot_is_not_taken_for_a_policy(tmp_path):
    from training.ppo.policy_io import STATE_FILE, find_snapshot, load_policy

    run = tmp_path / "run"
    shutil.copytree(POLICY, run, ignore=shutil.ignore_patterns("figures"))
    (run / "final" / STATE_FILE).unlink()  # killed before the snapshot was complete
    with pytest.raises(FileNotFoundError, match="has: \\['imitation'\\]"):
        find_snapshot(run, "final")
    (run / "final").rename(run / "final.tmp")
    shutil.copytree(POLICY / "final", run / "final.prev")  # the kept previous snapshot
    assert find_snapshot(run, "final") == run / "final.prev"
    load_policy(run, "final")


def test_committed_level2_policy_walks_with_no_recorded_motion():
    """policies/ppo_gait_50hz: the network alone sets torques every 20 ms, trained by PPO from a
    random network with the gait reward and the env's own starts; no option of its run-time or
    training env reads a recorded walk. One held-out 30 s mid-stride episode walks."""
    import torch

    from biped_constraint_env.settings import make_settings
    from training.plumbing.rollouts import run_episodes
    from training.ppo.policy_io import available, load_policy, policy_actor

    torch.set_num_threads(1)
    path = POLICY.parent / "ppo_gait_50hz"
    policy, norm, cfg, _ = load_policy(path, "best")
    assert cfg.teacher == "" and cfg.base_controller == "" and not available(path, "imitation")
    run, train = cfg.settings(), make_settings(**cfg.train_env_kwargs())
    for s in (run, train):
        assert s.reward.kind == "gait" and s.action.kind == "torque" and not s.needs_reference
        assert s.dt == 0.02 and s.observation.phase_obs and s.physics.options.strict
        assert s.physics.preset == "default"
    assert dict(train.start.start) == {"stride": 0.75, "midstride": 0.25}
    assert run.start.start == "midstride"
    (ep,) = run_episodes(policy_actor(policy, norm, cfg), cfg.env_kwargs(), [0], cfg.env_id,
                         episode_s=30)  # fmt: skip
    assert ep["steps_completed"] >= 20 and ep["end"] == "time_limit", ep


def test_committed_gait_rest_policy_starts_from_rest_with_no_recorded_motion():
    """policies/ppo_gait_rest_50hz: the network alone sets torques every 20 ms, trained by PPO
    from a random network with the gait reward and the env's own starts around rest (nudge
    starts with rates on both sides of zero); no option of its run-time or training env reads a
    recorded walk, and ``evaluate`` loads its published snapshot. One held-out 30 s episode from
    the paper's rest posture walks."""
    import torch

    from biped_constraint_env.settings import make_settings
    from biped_constraint_env.starts import NUDGE_RATE_RANGE_RAD_S
    from training.plumbing.rollouts import run_episodes
    from training.ppo.policy_io import available, load_policy, policy_actor, published_snapshot

    torch.set_num_threads(1)
    path = POLICY.parent / "ppo_gait_rest_50hz"
    assert published_snapshot(path)[0] == "best"
    policy, norm, cfg, _ = load_policy(path)  # the published snapshot, as evaluate loads it
    assert cfg.teacher == "" and cfg.base_controller == "" and not available(path, "imitation")
    run, train = cfg.settings(), make_settings(**cfg.train_env_kwargs())
    for s in (run, train):
        assert s.reward.kind == "gait" and s.action.kind == "torque" and not s.needs_reference
        assert s.dt == 0.02 and s.observation.phase_obs and s.physics.options.strict
    assert run.start.start == "rest" and "nudge" in dict(train.start.start)
    assert NUDGE_RATE_RANGE_RAD_S[0] < 0.0 < NUDGE_RATE_RANGE_RAD_S[1]
    (ep,) = run_episodes(policy_actor(policy, norm, cfg), cfg.env_kwargs(), [0], cfg.env_id,
                         episode_s=30)  # fmt: skip
    assert ep["steps_completed"] >= 20 and ep["end"] == "time_limit", ep
