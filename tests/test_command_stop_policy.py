"""The committed command policy that stops (policies/ppo_command_stop_50hz): its line of PPO
runs from random networks, checked by the weights' hashes each run recorded; its recipe's last
stage is the committed config; one held-out episode from rest walks, stops, stands and walks
again with the network alone in the loop."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from training.ppo.policy_io import read_config

ROOT = Path(__file__).resolve().parents[1]
POLICY = ROOT / "policies" / "ppo_command_stop_50hz"
CONFIG = ROOT / "training" / "configs" / "ppo_command_stop_50hz.toml"
WALKER = "policies/ppo_command_50hz"  # the three-stage walker: test_committed_policy checks it
STANDER = "results/command_stage5/r_stander"  # PPO from a random network, standing
RECORD_OF = {  # a kept snapshot's folder -> the folder holding its run's record
    "results/command_stage7/e2_walker": "results/command_stage6/e2_load_target_100_from_d2",
}
NOT_KEPT = {  # the weights of these runs' start snapshots were not kept: their records were
    "be29579ad750": "results/command_stage6/c1_hold_load",
    "5efd967d9592": "results/command_stage6/d2_load_target_100_from_c1",
    "a6625c761e63": "results/command_stage7/r1_stride_stander_lr_3e-5",
}


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _snapshots() -> dict[str, str]:
    """{weights sha256: the folder (relative to the repository) of the run that holds them}."""
    found = {}
    for top in ("policies", "results"):
        for f in (ROOT / top).rglob("policy.safetensors"):
            found.setdefault(_sha(f), str(f.parent.parent.relative_to(ROOT)))
    return found


def test_the_line_runs_by_recorded_hashes_from_random_networks_with_no_teacher():
    """Every run of the line records the weights it started from (init_from.json); each is
    found in the repository by its hash, but for three named runs whose start was not kept
    (their records are). The line ends at the three-stage walker (from a random network) and
    the stander (from a random network); no run has a teacher, a base controller or a reward
    that needs a recorded motion."""
    from biped_constraint_env.settings import make_settings

    snapshots = _snapshots()
    todo, seen, ends, unkept = [str(POLICY.relative_to(ROOT))], [], set(), set()
    while todo:
        folder = todo.pop()
        seen.append(folder)
        record = RECORD_OF.get(folder, folder)
        cfg = read_config(ROOT / record)
        assert cfg.teacher == "" and cfg.base_controller == "", record
        # the run's own training env: the command task's reward, no recorded motion
        s = make_settings(**read_config(ROOT / record).train_env_kwargs())
        assert s.task == "command" and s.reward.kind == "command" and not s.needs_reference
        if folder in (WALKER, STANDER):
            ends.add(folder)
            continue
        meta = json.loads((ROOT / record / "init_from.json").read_text())
        starts = [meta] + ([meta["stand_branch_from"]] if "stand_branch_from" in meta else [])
        for start in starts:
            sha = start["policy_sha256"]
            if sha in snapshots:
                todo.append(snapshots[sha])
            else:
                assert sha[:12] in NOT_KEPT, (record, start["policy"])
                unkept.add(sha[:12])
                todo.append(NOT_KEPT[sha[:12]])
    assert ends == {WALKER, STANDER} and unkept == set(NOT_KEPT)
    assert read_config(ROOT / STANDER).init_from == ""  # a random network
    assert len(seen) == 19  # the runs after the walker's three stages, and the two ends


def _recipe(*flags):
    from training.plumbing.common import parse_config
    from training.ppo.config import PPOConfig

    return parse_config(PPOConfig, ["--config", str(CONFIG), *flags], "")


def _differ(a, b) -> set[str]:
    return {f.name for f in dataclasses.fields(a) if getattr(a, f.name) != getattr(b, f.name)}


def test_the_recipes_last_stage_is_the_committed_config():
    """``train --config training/configs/ppo_command_stop_50hz.toml --seed 118`` is the run the
    policy is: every setting but the seed (and the progress bar; where a run writes is never
    read back)."""
    b = read_config(POLICY)
    assert _differ(_recipe("--seed", "118"), b) <= {"progress"}  # the run's: no progress bar
    assert b.env["command"] == {"deadband": 0.2, "ramp_m_s2": 1.5}  # the joystick options
    assert b.train_env["command"]["ramp_m_s2"] == 1.0  # its training's rate limit
    assert b.stand_branch and b.brake_branch and b.walker_frozen  # three actors, walker frozen
    # the comparison can fail: another seed, or the env without the joystick options
    assert _differ(_recipe("--seed", "119"), b) - {"progress"} == {"seed"}
    assert "env" in _differ(_recipe("--seed", "118", "--env", "command={}"), b)


def test_the_network_alone_walks_stops_stands_and_walks_again_from_rest():
    """One held-out episode (report seed 500000) from the paper's rest posture: 1.0 m/s for
    5 s, then 0 (at rest within 3 s, held 5 s: the protocol's test), then 1.0 m/s again."""
    import torch

    from biped_constraint_env.settings import make_settings
    from training.plumbing.command_protocol import period_speeds, run_commanded, stands
    from training.ppo.policy_io import available, load_policy, policy_batch_actor
    from training.ppo.stand_branch import StandBranchPolicy

    torch.set_num_threads(1)
    policy, norm, cfg, _ = load_policy(POLICY)
    assert isinstance(policy, StandBranchPolicy) and not available(POLICY, "imitation")
    run = cfg.settings()
    assert run.task == "command" and run.start.start == "rest" and not run.perturbations.active
    assert run.action.kind == "torque" and run.physics.options.strict
    train = make_settings(**cfg.train_env_kwargs())
    assert train.perturbations.push_impulse_ns and train.perturbations.slope_rad

    def command(t, k):
        return np.where(t < 5.0, 1.0, np.where(t < 13.0, 0.0, 1.0))

    (ep,) = run_commanded(policy_batch_actor(policy, norm, cfg), cfg.env_kwargs(), [500000],
                          command, 23.0)  # fmt: skip
    assert ep["end"] == "time_limit", ep["end"]
    t, v = period_speeds(ep)
    stood, drift = stands(t, v, 5.0, ep["t"][-1])
    assert stood and drift < 0.05
    assert len([s for s in ep["step_t_s"] if s < 5.0]) >= 4  # it walked first
    assert len([s for s in ep["step_t_s"] if s > 13.0]) >= 4  # and again
