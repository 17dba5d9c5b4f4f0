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

    from training.evaluation.rollouts import run_episodes
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


SCRATCH = POLICY.parent / "ppo_from_scratch"


def test_committed_from_scratch_policy_learned_without_a_teacher_and_walks():
    """policies/ppo_from_scratch: PPO from a random network (no teacher, no imitation), the
    network + PD about the reference at run time, walking from a held-out mid-stride start."""
    import torch

    from training.evaluation.rollouts import run_episodes
    from training.ppo.policy_io import available, load_policy, policy_actor

    torch.set_num_threads(1)
    policy, norm, cfg, state = load_policy(SCRATCH, "final")
    assert cfg.teacher == "" and cfg.base_controller == "" and cfg.bc_anchor_steps == 0
    assert not available(SCRATCH, "imitation")  # no warm start of any kind
    s = cfg.settings()
    assert s.reward.kind == "tracking" and s.action.pd
    assert cfg.train_env["start"]["kind"]["reference"] > 0  # reference states in training only
    assert s.start.reference_fraction == 0.0 and s.physics.preset == "default"
    assert s.start.start == "midstride"
    kw = cfg.env_kwargs()
    (ep,) = run_episodes(policy_actor(policy, norm, cfg), kw, [0], cfg.env_id)
    assert ep["steps_completed"] >= 20 and ep["end"] == "time_limit", ep


@pytest.mark.parametrize(
    "name, starts",
    [("ppo_walker_50hz", ("midstride", "rest")), ("ppo_alone_50hz", ("midstride",))],
)
def test_committed_50hz_policies_walk_at_20_ms_with_what_they_say_in_the_loop(name, starts):
    """The 50 Hz policies: PD targets every 20 ms (the PD law every 5 ms), trained by PPO from a
    random network; ppo_walker_50hz with the reference pose in the loop (and pushes and
    randomised models in training), ppo_alone_50hz the network alone (a fixed PD pose, the
    clock but no reference in its input). One held-out 30 s episode per start walks."""
    import torch

    from training.evaluation.rollouts import run_episodes
    from training.ppo.policy_io import available, load_policy, policy_actor

    torch.set_num_threads(1)
    path = POLICY.parent / name
    policy, norm, cfg, _ = load_policy(path, "best")
    assert cfg.teacher == "" and cfg.base_controller == "" and not available(path, "imitation")
    s = cfg.settings()
    assert s.dt == 0.02 and s.action.pd and s.action.pd_substeps == 4
    assert s.action.around == ("reference" if name == "ppo_walker_50hz" else "fixed")
    assert s.observation.phase_obs
    for start in starts:
        kw = {**cfg.env_kwargs(), "start": start}
        (ep,) = run_episodes(policy_actor(policy, norm, cfg), kw, [0], cfg.env_id, episode_s=30)
        assert ep["steps_completed"] >= 20 and ep["end"] == "time_limit", (start, ep)


def test_committed_level2_policy_walks_with_no_recorded_motion():
    """policies/ppo_gait_50hz: the network alone sets torques every 20 ms, trained by PPO from a
    random network with the gait reward and the env's own starts; no option of its run-time or
    training env reads a recorded walk. One held-out 30 s mid-stride episode walks."""
    import torch

    from biped_constraint_env.settings import make_settings
    from training.evaluation.rollouts import run_episodes
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
    from training.evaluation.rollouts import run_episodes
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


def test_committed_rest_policy_is_the_network_alone_and_starts_from_rest():
    """policies/ppo_alone_rest_50hz (the network alone from rest): it sets torques every 20 ms,
    the clock but no reference in its input, trained by PPO from a random network from both
    starts. One held-out 30 s episode from the paper's rest posture and one mid-stride walk."""
    import torch

    from training.evaluation.rollouts import run_episodes
    from training.ppo.policy_io import available, load_policy, policy_actor

    torch.set_num_threads(1)
    path = POLICY.parent / "ppo_alone_rest_50hz"
    policy, norm, cfg, _ = load_policy(path, "best")
    assert cfg.teacher == "" and cfg.base_controller == "" and not available(path, "imitation")
    s = cfg.settings()
    assert s.action.kind == "torque" and s.dt == 0.02 and s.physics.preset == "default"
    assert s.observation.phase_obs and s.start.reference_fraction == 0.0
    for start in ("rest", "midstride"):
        kw = {**cfg.env_kwargs(), "start": start}
        (ep,) = run_episodes(policy_actor(policy, norm, cfg), kw, [0], cfg.env_id, episode_s=30)
        assert ep["steps_completed"] >= 20 and ep["end"] == "time_limit", (start, ep)


def test_committed_command_policy_follows_a_command_from_rest_with_no_recorded_motion():
    """policies/ppo_command_50hz: the network alone sets torques every 20 ms with the command in
    its input, trained by PPO in three stages from a random network on the command task (no
    recorded motion in its reward, starts or input; each later stage starts from the one
    before's published snapshot, recorded by its weights' hash, and trains with pushes, slopes
    and randomised models). One held-out 30 s episode from rest at 1.0 m/s walks, near the
    command."""
    import hashlib
    import json

    import torch

    from biped_constraint_env.settings import make_settings
    from training.evaluation.command_protocol import run_commanded, stride_errors
    from training.ppo.policy_io import available, load_policy, policy_batch_actor

    torch.set_num_threads(1)
    stages = [POLICY.parent / f"ppo_command_stage{k}_50hz" for k in (1, 2)]
    path = POLICY.parent / "ppo_command_50hz"
    policy, norm, cfg, _ = load_policy(path)
    cfgs = [load_policy(p)[2] for p in stages] + [cfg]
    assert [c.init_from for c in cfgs] == [""] + [f"policies/{p.name}" for p in stages]
    for before, p in zip(stages, (stages[1], path), strict=True):
        record = json.loads((p / "init_from.json").read_text())
        weights = before / record["snapshot"] / "policy.safetensors"
        assert hashlib.sha256(weights.read_bytes()).hexdigest() == record["policy_sha256"]
    for c, p in zip(cfgs, (*stages, path), strict=True):
        assert c.teacher == "" and c.base_controller == "" and not available(p, "imitation")
        s = make_settings(**c.train_env_kwargs())
        assert s.task == "command" and s.reward.kind == "command" and not s.needs_reference
        assert s.action.kind == "torque" and s.command is not None and s.physics.options.strict
    train = make_settings(**cfg.train_env_kwargs())
    assert train.perturbations.push_impulse_ns and train.perturbations.slope_rad
    run = cfg.settings()
    assert run.start.start == "rest" and not run.perturbations.active
    (ep,) = run_commanded(policy_batch_actor(policy, norm, cfg), cfg.env_kwargs(), [500000],
                          lambda t, k: np.full(len(t), 1.0), 30.0)  # fmt: skip
    assert ep["end"] == "time_limit" and ep["steps_completed"] >= 20, ep["end"]
    assert np.mean(stride_errors(ep, 1.0)) < 0.1
