"""Stages inside one run: ``[[schedule]]`` entries (``PPOConfig.schedule``) and the protocol's
selection (``select_by = "protocol"``)."""

from __future__ import annotations

import copy
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from training.plumbing.common import read_config_file
from training.ppo.config import PPOConfig

ROOT = Path(__file__).resolve().parents[1]
RECIPE = ROOT / "training" / "configs" / "ppo_command_scratch_50hz.toml"
PUSHES = {"push_impulse_ns": [-1.0, 1.0], "push_interval_s": [2.0, 5.0]}


def _cfg(**kw) -> PPOConfig:
    cfg = PPOConfig(env={"task": "command"}, **kw)
    cfg.validate()
    return cfg


def test_each_entry_holds_from_its_step_until_the_next():
    cfg = _cfg(
        gamma=0.96, stand_branch=True, stand_gamma=0.99,
        train_env={"start": "rest"},
        schedule=(
            {"at": 1000, "train_env": {"perturbations": PUSHES}, "gamma": 0.97},
            {"at": 5000, "train_env": {"start": "midstride"}, "stand_gamma": 0.995},
        ),
    )  # fmt: skip
    assert [cfg.phase_at(n) for n in (0, 999, 1000, 4999, 5000, 10**9)] == [0, 0, 1, 1, 2, 2]
    assert cfg.train_env_kwargs(0) == {"task": "command", "start": "rest"}
    assert cfg.train_env_kwargs(1000) == {"task": "command", "start": "rest",
                                          "perturbations": PUSHES}  # fmt: skip
    # an entry's keys replace those in force: the pushes stay, the start changes
    assert cfg.train_env_kwargs(7000) == {"task": "command", "start": "midstride",
                                          "perturbations": PUSHES}  # fmt: skip
    assert [cfg.gamma_at(n) for n in (0, 1000, 5000)] == [0.96, 0.97, 0.97]
    assert [cfg.stand_gamma_at(n) for n in (0, 1000, 5000)] == [0.99, 0.99, 0.995]


@pytest.mark.parametrize(
    "schedule, match",
    [
        (({"at": 10},), "takes at"),
        (({"at": 10, "gama": 0.9},), "takes at"),
        (({"gamma": 0.9},), "takes at"),
        (({"at": 0, "gamma": 0.9},), "above the entry before"),
        (({"at": True, "gamma": 0.9},), "whole number"),
        (({"at": 10, "gamma": 0.9}, {"at": 10, "gamma": 0.95}), "above the entry before's"),
        (({"at": 10, "gamma": 1.5},), "gamma must be in"),
        (({"at": 10, "stand_gamma": 0.99},), "needs the run's --stand-gamma"),
        (({"at": 10, "train_env": {}},), "a table of"),
        (({"at": 10, "train_env": {"start": "nowhere"}},), "train_env:"),
        (({"at": 10, "train_env": {"task": "walk"}},), "changes the observation"),
        (({"at": 10, "train_env": {"render_mode": "rgb_array"}},), "render_mode"),
    ],
)
def test_a_wrong_entry_is_refused_naming_it(schedule, match):
    with pytest.raises(ValueError, match=match):
        _cfg(schedule=schedule)


def test_a_schedule_goes_with_neither_a_gamma_ramp_nor_a_start_curriculum():
    with pytest.raises(ValueError, match="both set the discount"):
        _cfg(gamma_final=0.98, gamma_ramp=(0, 10), schedule=({"at": 10, "gamma": 0.9},))
    with pytest.raises(ValueError, match="start_curriculum"):
        _cfg(start_curriculum={"first": "rest", "until_episode_s": 1.0},
             schedule=({"at": 10, "gamma": 0.9},))  # fmt: skip


def test_a_schedule_is_a_config_file_table_and_round_trips(tmp_path):
    from training.plumbing.common import Refusal, to_toml
    from training.ppo.policy_io import read_config
    from training.ppo.train import main

    with pytest.raises(Refusal, match="unrecognized arguments: --schedule"):
        main(["--schedule", "x"])
    bad = tmp_path / "bad.toml"
    bad.write_text('[env]\ntask = "command"\n[[schedule]]\nat = 5\ngamma = "0.9"\n')
    with pytest.raises(Refusal, match="gamma must be in"):
        main(["--config", str(bad), "--out-dir", str(tmp_path / "runs")])
    assert not (tmp_path / "runs").exists()  # refused before anything was written
    cfg = _cfg(schedule=({"at": 5, "train_env": {"perturbations": PUSHES}},))
    (tmp_path / "config.toml").write_text(to_toml(cfg))
    assert read_config(tmp_path) == cfg


def test_protocol_selection_needs_a_command():
    with pytest.raises(ValueError, match="needs an env with a command"):
        PPOConfig(select_by="protocol").validate()


def test_protocol_goals_and_score():
    from training.plumbing.command_protocol import goals, selection_score

    def rate(r):
        return {"success": {"rate": r}}

    rows = [{"row": "start", **rate(1.0)},
            {"row": "track", "mean_abs_error_m_s": 0.05, "ran_30s": 3, "episodes": 3},
            {"row": "stop", **rate(1.0), "drift_m_s_mean": 0.01}]  # fmt: skip
    assert goals(rows) == {"start": True, "track": True, "stop": True}
    best = selection_score(rows)
    worse = [rows[0], {**rows[1], "mean_abs_error_m_s": 0.2}, rows[2]]
    assert goals(worse)["track"] is False and selection_score(worse) < best
    drifting = [rows[0], rows[1], {**rows[2], "drift_m_s_mean": 0.06}]
    assert goals(drifting)["stop"] is False
    fell = [rows[0], {**rows[1], "ran_30s": 2}, rows[2]]
    assert goals(fell)["track"] is False
    # more goals met always ranks higher, whatever the rest
    assert selection_score(worse) >= 2 > selection_score([{**rows[0], **rate(0.9)}, worse[1],
                                                          drifting[2]])  # fmt: skip


def test_the_command_recipe_trains_from_random_weights_with_its_schedule_in_effect(
    tmp_path, monkeypatch
):
    """The recipe's config, its budget and schedule scaled down: every actor learns, the
    schedule's env begins at the first rollout at or after its step, and the protocol selects."""
    from training.plumbing import common
    from training.ppo import build, train
    from training.ppo.experts import ExpertsPolicy

    values = read_config_file(RECIPE)
    assert "init_from" not in values  # a random network to start
    pushes, stop = values["schedule"]
    assert "perturbations" in pushes["train_env"] and "stand" in stop["train_env"]["start"]
    rollout = 8 * 64
    schedule = [{**pushes, "at": rollout + 1}, {**stop, "at": 3 * rollout}]
    scaled = {**values, "schedule": schedule, "n_envs": 8, "n_steps": 64,
              "batch_size": 256, "total_timesteps": 5 * rollout, "eval_freq": 5 * rollout,
              "eval_episodes": 1, "checkpoint_freq": 5 * rollout}  # fmt: skip
    config = tmp_path / "recipe.toml"
    config.write_text(common.to_toml(replace(PPOConfig(), **{
        k: tuple(v) if isinstance(v, list) else v for k, v in scaled.items()})))  # fmt: skip

    made: list = []
    phase_env = build.phase_env

    def recording_phase_env(cfg, seed, env_steps, env_threads=None):
        venv = phase_env(cfg, seed, env_steps, env_threads)
        made.append((env_steps, venv.venv.settings))
        return venv

    gammas: list = []
    gamma_at = PPOConfig.gamma_at

    def recording_gamma_at(self, env_steps):
        gammas.append((env_steps, gamma_at(self, env_steps)))
        return gammas[-1][1]

    monkeypatch.setattr(PPOConfig, "gamma_at", recording_gamma_at)

    monkeypatch.setattr(build, "phase_env", recording_phase_env)
    models: list = []
    make_model = train.make_model

    def recording_make_model(*a, **kw):
        model = make_model(*a, **kw)
        models.append((model, copy.deepcopy(model.policy.state_dict())))
        return model

    monkeypatch.setattr(train, "make_model", recording_make_model)
    assert train.main(["--config", str(config), "--out-dir", str(tmp_path / "runs"),
                       "--progress", "false"]) == 0  # fmt: skip
    # each phase's env from the first rollout at or after its step: 0, 2 x 512, 3 x 512
    assert [n for n, _ in made] == [0, 2 * rollout, 3 * rollout]
    (_, first), (_, pushed), (_, stopping) = made
    assert first.perturbations.push_impulse_ns is None
    assert pushed.perturbations.push_impulse_ns == stopping.perturbations.push_impulse_ns
    assert pushed.perturbations.push_impulse_ns == (-1.0, 1.0)
    assert first.command.zero_fraction == pushed.command.zero_fraction == 0.1
    assert stopping.command.zero_fraction == 0.3 and stopping.reward.weights != first.reward.weights
    # the discount before every rollout: the config's, then the stop phase's from 3 x 512
    assert {g for n, g in gammas if n < 3 * rollout} == {values["gamma"]}
    assert {g for n, g in gammas if n >= 3 * rollout} == {stop["gamma"]}
    ((model, initial),) = models
    assert isinstance(model.policy, ExpertsPolicy)
    assert [name for name, _, _ in model.policy.experts] == ["stand", "brake"]
    final = model.policy.state_dict()
    for actor in ("mlp_extractor.policy_net.0.weight", "actors.0.0.weight", "actors.1.0.weight",
                  "critics.stand.0.0.weight"):  # fmt: skip
        assert not torch.equal(final[actor], initial[actor]), actor  # every actor learned
    (run,) = (tmp_path / "runs" / "train_ppo").iterdir()
    eval_csv = (run / "eval.csv").read_text()
    assert "goals_met" in eval_csv and "/9" in eval_csv  # the protocol's nine goals were read
    import json

    assert "the command protocol's goals met" in json.loads(
        (run / "published.json").read_text())["why"]  # fmt: skip
    # the run's weights load as any policy (no code, no pickle) and act as the trained network
    import numpy as np

    from training.ppo.policy_io import ObsNormalizer, open_policy
    from training.ppo.policy_io import main as policy_io

    loaded, norm, saved_cfg, _, _ = open_policy(run, "final")
    assert saved_cfg.schedule == tuple(schedule)  # the run's own config
    obs = np.random.default_rng(0).normal(size=(32, loaded.observation_space.shape[0]))
    obs[::2, saved_cfg.obs_names().index("command_m_s")] = 0.0
    x = ObsNormalizer(norm)(obs)
    want, _ = model.policy.predict(x, deterministic=True)
    got, _ = loaded.predict(x, deterministic=True)
    np.testing.assert_array_equal(got, want)
    pytest.importorskip("onnxruntime")  # the export checks onnxruntime's actions itself
    assert policy_io(["export-onnx", str(run), str(tmp_path / "p.onnx")]) == 0


def test_a_scheduled_learning_rate_is_adams_from_its_step_under_the_runs_decay():
    """SB3 sets Adam's rate from the model's schedule before each update: a scheduled rate
    replaces the config's from its step, decayed as the config's would be."""
    from types import SimpleNamespace as NS

    from stable_baselines3.common.utils import LinearSchedule

    from training.ppo.callbacks import gamma_schedule

    cfg = _cfg(learning_rate=3e-4, lr_schedule="linear", total_timesteps=1_000_000,
               schedule=({"at": 500_000, "learning_rate": 1e-5},))  # fmt: skip
    assert cfg.learning_rate_at(250_000) == pytest.approx(LinearSchedule(3e-4, 0.0, 1.0)(0.75))
    assert cfg.learning_rate_at(600_000) == pytest.approx(1e-5 * 0.4)
    vecnorm = NS(gamma=0.0)
    model = NS(num_timesteps=0, gamma=0.0, rollout_buffer=NS(gamma=0.0), lr_schedule=None,
               logger=NS(record=lambda *a: None), get_env=lambda: None)  # fmt: skip
    cb = gamma_schedule(cfg, vecnorm)
    cb.init_callback(model)
    for steps, want in ((100_000, 3e-4 * 0.9), (750_000, 1e-5 * 0.25)):
        model.num_timesteps = steps
        cb.on_rollout_start()
        cb.on_rollout_end()
        assert model.lr_schedule(0.123) == pytest.approx(want)
