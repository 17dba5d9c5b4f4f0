"""Scripts and SB3 on the env with tiny budgets (smoke)."""

import dataclasses
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from training.paper import open_loop


def test_open_loop_writes_run_directory(tmp_path):
    rc = open_loop.main(["--out-dir", str(tmp_path), "--max-periods", "20", "--progress", "false"])
    assert rc == 0
    (run,) = (tmp_path / "open_loop").iterdir()
    for name in (
        "config.toml",
        "command.txt",
        "versions.json",
        "summary.json",
        "figures/strip.png",
        "figures/modes.png",
        "figures/walk.gif",
    ):
        assert (run / name).is_file(), name
    summary = json.loads((run / "summary.json").read_text())
    assert summary["steps_completed"] >= 0 and summary["end_reason"] is not None


def test_open_loop_config_file_and_flags(tmp_path):
    cfg_file = tmp_path / "c.toml"
    cfg_file.write_text('preset = "default"\ndt = 0.002\nsigns = [1, -1, 1, -1, 1]\n')
    cfg = open_loop.parse_config(
        open_loop.OpenLoopConfig, ["--config", str(cfg_file), "--dt", "0.004"], "x"
    )
    assert cfg.preset == "default" and cfg.dt == 0.004 and cfg.signs == (1, -1, 1, -1, 1)


def test_open_loop_noisy_starts_use_the_config_start():
    """The noisy starts are the config's start plus the env's noise law, seed by seed."""
    from biped_constraint_env.starts import midstride_start

    q, qd = midstride_start(-1.0, -0.2)
    cfg = open_loop.OpenLoopConfig(
        preset="default",
        dt=0.02,
        stop_at_switch=True,
        max_periods=5,
        gif=False,
        progress=False,
        torques=(0.0,) * 20,
        posture=tuple(q),
        velocity=tuple(qd),
        mode=2,
        noise_seeds=2,
        noise=0.01,
    )
    exact = open_loop.run(cfg, record_frames=True)
    first = exact["frames"][0]["keypoints"]
    runs = open_loop.noisy_starts(cfg)
    assert [r["seed"] for r in runs] == [0, 1]
    again = open_loop.run(cfg, record_frames=True, reset_seed=0, noise=0.01)
    moved = np.abs(again["frames"][0]["keypoints"]["hip"] - first["hip"]).max()
    assert 0 < moved < 0.05  # noise of 0.01 rad on q1..q5 moves the hip, but only a little
    assert again["steps_completed"] == runs[0]["steps_completed"]
    with pytest.raises(ValueError, match="6 values"):
        open_loop.run(open_loop.OpenLoopConfig(velocity=(1.0,), gif=False), record_frames=False)


def test_optimize_open_loop_midstride_smoke(tmp_path):
    from training.paper import optimize_open_loop

    args = ["--out-dir", str(tmp_path), "--start", "midstride", "--iterations", "2"]
    args += ["--population", "16", "--restarts", "1", "--seconds", "0.5", "--progress", "false"]
    assert optimize_open_loop.main(args) == 0
    (run,) = (tmp_path / "optimize_open_loop").iterdir()
    summary = json.loads((run / "summary.json").read_text())
    assert len(summary["robustness_steps_10_seeds"]) == 10
    cfg = open_loop.parse_config(
        open_loop.OpenLoopConfig, ["--config", str(run / "best_open_loop.toml")], "x"
    )
    assert cfg.mode == 2 and cfg.stop_at_switch and len(cfg.velocity) == 6


def test_sb3_ppo_learns_2048_steps(tmp_path):
    import torch
    from gymnasium.wrappers import RescaleAction
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    lo, hi = np.full(5, -1.0, np.float32), np.full(5, 1.0, np.float32)
    env = RescaleAction(gym.make("ConstrainedBiped-v0", task="paper", preset="default"), lo, hi)
    model = PPO("MlpPolicy", env, n_steps=512, batch_size=128, n_epochs=2, seed=0, device="cpu")
    model.learn(total_timesteps=2048)
    assert model.num_timesteps >= 2048
    model.save(tmp_path / "m.zip")
    assert (tmp_path / "m.zip").is_file()


def test_paper_preset_baseline_is_deterministic_and_documented():
    """README, Reproducing Table 2: 0 steps; 1 -> 2 at t = 0, then a body point below ground."""
    cfg = open_loop.OpenLoopConfig(gif=False, progress=False)
    a = open_loop.run(cfg, record_frames=False)
    b = open_loop.run(cfg, record_frames=False)
    assert a["switches"] == b["switches"] and a["t_end_s"] == b["t_end_s"]
    assert a["steps_completed"] == 0
    assert [tuple(s[1:]) for s in a["switches"]] == [(1, 2)]
    assert a["end_reason"] == "body_below_ground"
    assert a["t_end_s"] == pytest.approx(0.14, abs=1e-9)


def test_train_ppo_and_evaluate_smoke(tmp_path):
    from training.evaluation import evaluate
    from training.ppo import train as train_ppo

    rc = train_ppo.main(
        [
            "--out-dir",
            str(tmp_path),
            "--total-timesteps",
            "512",
            "--n-envs",
            "2",
            "--n-steps",
            "128",
            "--batch-size",
            "64",
            "--n-epochs",
            "1",
            "--eval-freq",
            "256",
            "--eval-episodes",
            "1",
            "--checkpoint-freq",
            "256",
            "--progress",
            "false",
        ]
    )
    assert rc == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    assert json.loads((run / "env_settings.json").read_text())["env"]["task"] == "walk"
    for name in (
        "config.toml",
        "command.txt",
        "versions.json",
        "final/policy.safetensors",
        "final/normalizer.npz",
        "final/state.json",
        "0.monitor.csv",
        "eval.csv",
        "checkpoints/latest/optimizer.safetensors",
        "checkpoints/latest/state.json",
        "best/policy.safetensors",
        "figures/learning_curve.png",
    ):
        assert (run / name).exists(), name
    assert not list(run.glob("**/*.pkl")) and not list(run.glob("**/*.zip"))  # nothing pickled
    assert any((run / "tb").iterdir())
    # a resume with a new total continues the step count from the checkpoint
    rc = train_ppo.main(["--resume", str(run), "--total-timesteps", "768", "--progress", "false"])
    assert rc == 0
    from training.ppo.policy_io import load_state

    assert load_state(run / "final")["num_timesteps"] >= 768
    assert (run / "512.monitor.csv").is_file()  # the resumed session's own monitor
    out = tmp_path / "eval"
    assert evaluate.main([str(run), "--episodes", "2", "--out", str(out)]) == 0
    summary = json.loads((out / "evaluation.json").read_text())
    (policy,) = summary["results"]
    assert summary["seeds"] == [500_000, 500_001] and len(policy["episodes"]) == 2  # report seeds
    assert policy["success"]["episodes"] == 2 and "ci95" in policy["success"]
    assert (out / "figures" / "best.gif").is_file()
    assert not (run / "evaluation.json").exists()  # the run directory is only read


def test_a_second_stage_starts_from_a_policys_published_snapshot(tmp_path):
    import torch

    from training.ppo import train as train_ppo
    from training.ppo.policy_io import load_policy, published_snapshot

    src = Path(__file__).resolve().parents[1] / "policies" / "ppo_command_stage1_50hz"
    flags = ["--config", str(src / "config.toml"), "--total-timesteps", "64", "--n-envs", "2",
             "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1", "--eval-freq", "1000",
             "--checkpoint-freq", "64", "--progress", "false",
             "--learning-rate", "1e-12"]  # fmt: skip
    rc = train_ppo.main([*flags, "--out-dir", str(tmp_path), "--init-from", str(src)])
    assert rc == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    record = json.loads((run / "init_from.json").read_text())
    assert record["snapshot"] == published_snapshot(src)[0] and len(record["policy_sha256"]) == 64
    new, *_ = load_policy(run, "final")
    old, *_ = load_policy(src)
    for (k, a), b in zip(new.state_dict().items(), old.state_dict().values(), strict=True):
        if k == "log_std":  # a new run's initial exploration noise is its config's
            assert a.tolist() == pytest.approx([-5.0, -4.0, -4.0, -3.5, -3.0])
        else:  # a vanishing learning rate: the start's weights
            assert torch.allclose(a, b, atol=1e-6), k
    bad = tmp_path / "none"
    with pytest.raises(SystemExit, match="no such policy directory"):
        train_ppo.main([*flags, "--out-dir", str(tmp_path / "b"), "--init-from", str(bad)])


def test_a_second_stage_with_a_fresh_normaliser_keeps_the_weights_not_the_statistics(tmp_path):
    from training.ppo import train as train_ppo
    from training.ppo.policy_io import NORMALIZER_FILE, open_snapshot, read_normalizer

    src = Path(__file__).resolve().parents[1] / "policies" / "ppo_command_stage1_50hz"
    flags = ["--config", str(src / "config.toml"), "--total-timesteps", "64", "--n-envs", "2",
             "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1", "--eval-freq", "1000",
             "--checkpoint-freq", "64", "--progress", "false", "--learning-rate", "1e-12",
             "--init-from", str(src)]  # fmt: skip

    def statistics(where, which):
        snap = open_snapshot(where, which)
        return read_normalizer("n", 27, snap.files[NORMALIZER_FILE])

    old = statistics(src, "best")
    for mode in ("snapshot", "fresh"):
        out = tmp_path / mode
        assert train_ppo.main([*flags, "--out-dir", str(out), "--init-normalizer", mode]) == 0
        (run,) = (out / "train_ppo").iterdir()
        assert json.loads((run / "init_from.json").read_text())["normalizer"] == mode
        new = statistics(run, "final")
        # the run's own observations: 64 steps and the 2 rows' first resets
        if mode == "snapshot":  # added to the policy's statistics
            assert new["obs_count"] - old["obs_count"] == pytest.approx(66)
        else:  # alone (SB3 starts a count at 1e-4)
            assert new["obs_count"] == pytest.approx(66, abs=1e-3)
            assert not np.allclose(new["obs_mean"], old["obs_mean"])
    with pytest.raises(SystemExit, match="init-normalizer goes with --init-from"):
        train_ppo.main([*flags[:-2], "--out-dir", str(tmp_path / "x"), "--init-normalizer",
                        "fresh"])  # fmt: skip


def test_a_second_stage_that_observes_more_starts_from_the_same_function(tmp_path):
    from training.ppo import train as train_ppo
    from training.ppo.policy_io import load_policy, policy_batch_actor
    from training.ppo.widen import added_entries

    assert added_entries(("phase", "command"), ("phase", "gravity", "command")) == [26, 27]
    assert added_entries(("command",), ("gravity", "phase", "command")) == [24, 25, 26, 27]
    with pytest.raises(ValueError, match="in order"):
        added_entries(("phase", "command"), ("command", "phase"))
    src = Path(__file__).resolve().parents[1] / "policies" / "ppo_command_stage1_50hz"
    flags = ["--config", str(src / "config.toml"), "--total-timesteps", "64", "--n-envs", "2",
             "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1", "--eval-freq", "1000",
             "--checkpoint-freq", "64", "--progress", "false", "--learning-rate", "1e-12",
             "--init-from", str(src)]  # fmt: skip
    gravity = ["--env", 'observation=["phase", "gravity"]']
    assert train_ppo.main([*flags, *gravity, "--out-dir", str(tmp_path / "a")]) == 0
    (run,) = (tmp_path / "a" / "train_ppo").iterdir()
    assert json.loads((run / "init_from.json").read_text())["added_inputs"] == [26, 27]
    new, new_norm, cfg, _ = load_policy(run, "final")
    old, old_norm, old_cfg, _ = load_policy(src)
    assert cfg.obs_dim() == 29 and old_cfg.obs_dim() == 27
    # the added entries' statistics from the training env's starts: flat ground in stage 1
    np.testing.assert_allclose(new_norm.mean[26:28], [0.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(new_norm.var[26:28], [1e-6, 1e-6], rtol=1e-3)  # + 66 samples
    rng = np.random.default_rng(0)
    obs = rng.normal(0.0, 1.0, (64, 27)) * np.sqrt(old_norm.var) + old_norm.mean
    slope = rng.uniform(-0.1, 0.1, 64)
    wide = np.concatenate([obs[:, :26], -np.sin(slope)[:, None], -np.cos(slope)[:, None],
                           obs[:, 26:]], axis=1)  # fmt: skip
    a_new = policy_batch_actor(new, new_norm, cfg)(wide)
    a_old = policy_batch_actor(old, old_norm, old_cfg)(obs)
    assert np.abs(a_new - a_old).max() < 1e-3  # N m: the same function, gravity read with weight 0
    dropped = ["--env", 'observation=["gravity"]']  # the start read the clock: not a widening
    with pytest.raises(SystemExit, match="do not hold the start's"):
        train_ppo.main([*flags, *dropped, "--out-dir", str(tmp_path / "b")])


def test_a_network_with_a_standing_branch_widens_to_the_same_function(tmp_path):
    """The stop policy (a walker, a braking actor and a standing branch) widened for the gravity
    entries: every head and both critics compute what the start computed, whatever the slope."""
    import torch

    from training.ppo import train as train_ppo
    from training.ppo.policy_io import load_policy

    src = Path(__file__).resolve().parents[1] / "policies" / "ppo_command_stop_50hz"
    flags = ["--config", str(src / "config.toml"), "--total-timesteps", "64", "--n-envs", "2",
             "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1", "--eval-freq", "1000",
             "--checkpoint-freq", "64", "--progress", "false", "--learning-rate", "1e-12",
             "--init-from", str(src), "--env", 'observation=["phase", "gravity"]',
             "--out-dir", str(tmp_path)]  # fmt: skip
    assert train_ppo.main(flags) == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    new, new_norm, cfg, _ = load_policy(run, "final")
    old, old_norm, _, _ = load_policy(src)
    rng = np.random.default_rng(1)
    obs = rng.normal(0.0, 1.0, (64, 27)) * np.sqrt(old_norm.var) + old_norm.mean
    obs[:32, 17:21] = [0.0, 0.0, 0.0, 1.0]  # model 4 at a zero command: the branch's rows
    obs[:32, 26] = 0.0
    obs[32:48, 17:21] = [1.0, 0.0, 0.0, 0.0]  # model 1 at a zero command: the braking actor's
    obs[32:48, 26] = 0.0
    slope = rng.uniform(-0.1, 0.1, 64)
    wide = np.concatenate([obs[:, :26], -np.sin(slope)[:, None], -np.cos(slope)[:, None],
                           obs[:, 26:]], axis=1)  # fmt: skip
    with torch.no_grad():
        x_old = torch.as_tensor(old_norm(obs), dtype=torch.float32)
        x_new = torch.as_tensor(new_norm(wide), dtype=torch.float32)
        assert old.gate(x_old)[:32].all() and not old.gate(x_old)[32:].any()
        assert torch.equal(new.gate(x_new), old.gate(x_old))
        assert old.brake_gate(x_old)[32:48].all() and not old.brake_gate(x_old)[:32].any()
        assert torch.equal(new.brake_gate(x_new), old.brake_gate(x_old))
        v_old, v_new = old.predict_values(x_old), new.predict_values(x_new)
        f_old, f_new = old.extract_features(x_old), new.extract_features(x_new)
        b_old, b_new = old.branch_values(f_old), new.branch_values(f_new)  # every row
        m_old, m_new = old.branch_mean(f_old), new.branch_mean(f_new)
        a_old = old.get_distribution(x_old).distribution.mean
        a_new = new.get_distribution(x_new).distribution.mean
    for a, b in ((v_old, v_new), (b_old, b_new)):  # the critics, in the runs' return units
        assert (a - b).abs().max() < 1e-4 * (1 + a.abs().max())
    assert (m_old - m_new).abs().max() < 1e-5  # the standing head on every row
    assert (a_old - a_new).abs().max() < 1e-5  # actions: the same function, gravity weight 0
    assert old.brake_branch and new.brake_branch  # the published network brakes with its own actor


def test_tracking_config_trains_evaluates_without_reference_starts_and_compares(
    tmp_path, monkeypatch
):
    """The from-scratch recipe's pipeline: PD targets, tracking reward, reference starts in
    training only; evaluate and compare_runs rebuild the run-time env from the config."""
    from training.evaluation import compare as compare_runs
    from training.ppo import train as train_ppo
    from training.ppo.policy_io import load_policy, read_config

    small = ["--total-timesteps", "512", "--n-envs", "4", "--n-steps", "64", "--batch-size",
             "128", "--n-epochs", "1", "--eval-freq", "256", "--eval-episodes", "1",
             "--checkpoint-freq", "256", "--progress", "false"]  # fmt: skip
    small += ["--out-dir", str(tmp_path)]
    config = "training/configs/ppo_from_scratch.toml"
    assert train_ppo.main(["--config", config, *small]) == 0
    relu = ["--seed", "1", "--train-env", 'start="midstride"', "--activation", "relu"]
    assert train_ppo.main(["--config", config, *small, *relu]) == 0
    with pytest.raises(SystemExit, match="activation"):
        train_ppo.main(["--config", config, *small, "--activation", "sigmoid"])
    run0, run1 = sorted((tmp_path / "train_ppo").iterdir())
    cfg = read_config(run0)
    s = cfg.settings()
    from biped_constraint_env.settings import make_settings

    train = make_settings(**cfg.train_env_kwargs())
    assert s.action.pd and s.reward.kind == "tracking" and train.start.reference_fraction == 0.5
    assert cfg.env_kwargs()["start"]["kind"] == "midstride"  # task "track" less its references
    assert s.start.reference_fraction == 0.0
    assert s.action.offset[1][0] > 0 and read_config(run1).train_env == {"start": "midstride"}
    kinds = [{type(m).__name__ for m in load_policy(r)[0].modules()} for r in (run0, run1)]
    assert "Tanh" in kinds[0] and "ReLU" not in kinds[0] and "ReLU" in kinds[1]
    seen = []
    real = compare_runs.run_episodes

    def spy(actor, env_kwargs, seeds, env_id, episode_s=None, desc=""):
        seen.append(env_kwargs)
        assert episode_s == 30.0  # report episodes: 30 s at any control period
        return real(actor, env_kwargs, seeds, env_id, episode_s=episode_s, desc=desc)

    monkeypatch.setattr(compare_runs, "run_episodes", spy)
    out = tmp_path / "compare.json"
    argv = [str(run0), str(run1), "--which", "final", "--episodes", "2", "--out", str(out)]
    assert compare_runs.main([*argv, "--curves", str(tmp_path / "curves.png")]) == 0
    assert (tmp_path / "curves.png").stat().st_size > 0
    rows = json.loads(out.read_text())["rows"]
    assert [r["training_seed"] for r in rows] == [0, 1]
    assert rows[1]["changes"] == "train_env.start='midstride', activation='relu'"
    assert "PD" in rows[0]["in_the_loop"]
    assert all(kw["task"] == "track" for kw in seen)
    assert all(make_settings(**kw).start.start == "midstride" for kw in seen)  # no references


@pytest.mark.parametrize(
    ("toml", "match"),
    [
        ("curriculum_steps = 0\n", "curriculum_steps: removed"),
        ("[curriculum_env]\nstrict = false\n", "curriculum_env: removed"),
        ("[env]\nrestarts = 0.5\n", "restarts: removed"),
        ("[train_env]\nreference_obs = true\n", "reference_obs: removed"),
    ],
)
def test_retired_settings_are_refused_by_name(tmp_path, toml, match):
    """Options that never produced a walker are gone; a config naming one is refused in one
    line that says so (the package is unreleased: no aliases)."""
    from training.ppo import train as train_ppo

    cfg = tmp_path / "old.toml"
    cfg.write_text(toml)
    with pytest.raises(SystemExit, match=match) as e:
        train_ppo.main(["--config", str(cfg), "--out-dir", str(tmp_path / "runs")])
    assert "\n" not in str(e.value) and not (tmp_path / "runs").exists()


def test_train_ppo_help_explains_every_setting(capsys):
    from training.plumbing.common import field_help
    from training.ppo import train as train_ppo
    from training.ppo.config import PPOConfig

    helps = field_help(PPOConfig)
    assert all(helps[f.name] for f in dataclasses.fields(PPOConfig)), helps
    with pytest.raises(SystemExit):
        train_ppo.main(["--help"])
    out = capsys.readouterr().out
    assert "DAgger rounds" in out and "(default: 0.0003)" in out


def test_table2_study_smoke(tmp_path):
    from training.paper import table2_study

    rc = table2_study.main(
        [
            "--out-dir",
            str(tmp_path),
            "--postures",
            "2",
            "--seconds",
            "0.2",
            "--refine-iterations",
            "1",
            "--progress",
            "false",
        ]
    )
    assert rc == 0
    (run,) = (tmp_path / "table2_study").iterdir()
    summary = json.loads((run / "summary.json").read_text())
    assert len(summary["option_sets"]) == 24 and "best_strict" in summary
    assert (run / "figures" / "end_reasons.png").is_file()


def test_optimised_table_documented_step_counts():
    """README: 1 step with exact torque switching (simulator and env with stop_at_switch, 20 ms),
    0 through the env when the torque is held to the end of a 2 ms period; strict physics."""
    import tomllib
    from pathlib import Path

    from biped_constraint_env import paper_biped
    from biped_constraint_env.simulator import DEFAULT_OPTIONS, SimState, step

    path = Path(__file__).parents[1] / "training" / "configs" / "open_loop_optimised.toml"
    cfg_dict = tomllib.loads(path.read_text())
    table = np.array(cfg_dict["torques"]).reshape(4, 5)
    st = SimState(0.0, 1, 0, np.array(cfg_dict["posture"]), np.zeros(6))
    params = paper_biped()
    for _ in range(500):
        res = step(params, st, table, 0.02, DEFAULT_OPTIONS)
        st = res.state
        if res.terminated:
            break
    assert st.steps_completed == 1
    cfg = open_loop.parse_config(open_loop.OpenLoopConfig, ["--config", str(path)], "x")
    quiet = dataclasses.replace(cfg, gif=False, progress=False)
    out = open_loop.run(quiet, record_frames=False)
    assert cfg.stop_at_switch and out["steps_completed"] == 1
    assert out["distance_m"] < -0.9  # the one step goes backwards (README)
    held = dataclasses.replace(quiet, stop_at_switch=False, dt=0.002, max_periods=5000)
    out = open_loop.run(held, record_frames=False)
    assert out["steps_completed"] == 0 and out["end_reason"] == "stance_toe_pulls"


def test_optimised_midstride_table_documented_step_count():
    """README: the mid-stride table walks 1 step forward through the env, then stops."""
    from pathlib import Path

    path = Path(__file__).parents[1] / "training/configs/open_loop_optimised_midstride.toml"
    cfg = open_loop.parse_config(open_loop.OpenLoopConfig, ["--config", str(path)], "x")
    out = open_loop.run(dataclasses.replace(cfg, gif=False, progress=False), record_frames=False)
    assert out["steps_completed"] == 1 and out["end_reason"] == "step_behind_stance_toe"
    assert 1.2 < out["distance_m"] < 1.3


def test_sweep_without_ray_says_what_to_install(monkeypatch):
    import sys

    from training.ppo import sweep

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    with pytest.raises(SystemExit) as e:
        sweep.main(["--config", "training/configs/ppo_scratch.toml"])
    assert ".[distributed]" in str(e.value)  # the one line printed on exit


def test_teacher_gains_are_found_from_any_directory(monkeypatch, tmp_path):
    from training.controller.model_controller import controller_from

    monkeypatch.chdir(tmp_path)  # e.g. a Ray Tune trial's own directory
    controller_from("model:teacher_robust")
    with pytest.raises(ValueError, match="teacher_robust"):
        controller_from("model:no_such_gains")


def test_accuracy_quick_run_keeps_the_default_tolerance():
    """--quick once printed "meets_rule": false: its subset skipped the default's tolerance."""
    from benchmarks.accuracy import quick_tolerances
    from biped_constraint_env.simulator import DEFAULT_OPTIONS

    assert DEFAULT_OPTIONS.step_tol in quick_tolerances()


def test_benchmarks_name_their_extra_before_any_work(monkeypatch, capsys):
    import sys

    from benchmarks import accuracy, bench_env

    monkeypatch.setitem(sys.modules, "mujoco", None)
    with pytest.raises(SystemExit):
        bench_env.main(["--steps", "10"])
    assert ".[bench]" in capsys.readouterr().err
    assert ".[bench]" in accuracy.mujoco_validation(None)["skipped"]


def test_bench_ppo_takes_train_ppo_flags_on_top_of_the_config():
    """``python -m benchmarks.bench_ppo [--config C] FLAGS``: FLAGS are train_ppo's, applied
    over the config (a variant is timed as it would train); a misspelt flag is refused."""
    from benchmarks.bench_ppo import DEFAULT_CONFIG, _config

    base = _config(DEFAULT_CONFIG)
    cfg = _config(DEFAULT_CONFIG, ["--net-arch", "64", "64", "--n-envs", "128"])
    assert cfg.net_arch == (64, 64) and cfg.n_envs == 128
    assert cfg.env == base.env and cfg.n_steps == base.n_steps  # the rest: the config's
    with pytest.raises(SystemExit):
        _config(DEFAULT_CONFIG, ["--net-arch", "64", "--no-such-flag", "1"])


def test_sweep_assignments_reach_the_env_tables():
    """``--grid env.dt=0.01,0.02``: an entry of a config's env table; plain keys stay fields."""
    from training.ppo.sweep import parse_assignments

    grid = parse_assignments(["env.dt=0.01,0.02", "learning_rate=1e-4"], "--grid", grid=True)
    assert grid == {"env.dt": ["0.01", "0.02"], "learning_rate": ["1e-4"]}
    for bad in ("env=1", "surprise=1", "train_env.=1"):
        with pytest.raises(ValueError, match="not a settable"):
            parse_assignments([bad], "--set", grid=False)


def test_env_table_flags_go_on_top_of_the_config_table():
    """``--env KEY=VALUE``: TOML values over the config file's [env] entries, checked by the
    env's own settings check; the saved config holds the merged table."""
    from training.plumbing.common import parse_config, to_toml
    from training.ppo.config import PPOConfig

    cfg = parse_config(PPOConfig, ["--config", "training/configs/ppo_from_scratch.toml",
                                   "--env", "dt=0.02", 'start="rest"'], "")  # fmt: skip
    assert cfg.env["dt"] == 0.02 and cfg.env["start"] == "rest"
    assert cfg.env["task"] == "track" and cfg.train_env == {}  # the file's
    assert cfg.settings().dt == 0.02 and cfg.settings().action.pd
    import tomllib

    assert tomllib.loads(to_toml(cfg))["env"] == cfg.env  # round trip
    # a table flag given twice keeps both flags' items (the later wins a key given twice)
    cfg = parse_config(PPOConfig, ["--env", "dt=0.02", 'start="rest"', "--env", 'start="stand"',
                                   "--train-env", 'start="rest"', "--train-env",
                                   "termination={max_model_time_s=1.5}"], "")  # fmt: skip
    assert cfg.env == {"dt": 0.02, "start": "stand"}
    assert cfg.train_env == {"start": "rest", "termination": {"max_model_time_s": 1.5}}
    with pytest.raises(SystemExit, match="dt must be"):
        parse_config(PPOConfig, ["--env", "dt=-1"], "")
    with pytest.raises(SystemExit, match="KEY=VALUE"):
        parse_config(PPOConfig, ["--env", "dt"], "")


def test_a_recipe_is_its_base_plus_its_own_settings(tmp_path):
    """``base = "ppo_base.toml"``: the recipe's values on top of the base's, tables key by key;
    a base must be a file name in the recipe's folder, with no base of its own."""
    from training.plumbing.common import parse_config
    from training.ppo.config import PPOConfig

    (tmp_path / "b.toml").write_text('n_envs = 8\ngamma = 0.9\n[env]\ndt = 0.02\nstart = "rest"\n')
    (tmp_path / "r.toml").write_text('base = "b.toml"\ngamma = 0.95\n[env]\nstart = "mixed"\n')
    cfg = parse_config(PPOConfig, ["--config", str(tmp_path / "r.toml")], "")
    assert (cfg.n_envs, cfg.gamma, cfg.env) == (8, 0.95, {"dt": 0.02, "start": "mixed"})
    for bad, why in (('"../b.toml"', "a file name in the same folder"),
                     ('"/etc/passwd"', "a file name in the same folder"),
                     ('"r.toml"', "a base names no base of its own")):  # fmt: skip
        (tmp_path / "x.toml").write_text(f"base = {bad}\n")
        with pytest.raises(SystemExit, match=why):
            parse_config(PPOConfig, ["--config", str(tmp_path / "x.toml")], "")
    shipped = parse_config(PPOConfig, ["--config", "training/configs/ppo_gait_50hz.toml"], "")
    assert shipped.n_envs == 64 and shipped.action_bias_nm[0] == 12.0  # base, then its own


def test_a_discount_ramp_sets_gamma_where_sb3_reads_it_before_each_rollout():
    from types import SimpleNamespace as NS

    from training.ppo.callbacks import gamma_schedule
    from training.ppo.config import PPOConfig

    cfg = PPOConfig(gamma=0.9606, gamma_final=0.98, gamma_ramp=(2_000_000, 4_000_000))
    cfg.validate()
    assert [cfg.gamma_at(n) for n in (0, 2_000_000, 4_000_000, 9_000_000)] == [
        0.9606, 0.9606, 0.98, 0.98]  # fmt: skip
    vecnorm = NS(gamma=0.0)
    model = NS(num_timesteps=3_000_000, gamma=0.0, rollout_buffer=NS(gamma=0.0),
               logger=NS(record=lambda *a: None), get_env=lambda: None)  # fmt: skip
    cb = gamma_schedule(cfg, vecnorm)
    cb.init_callback(model)
    cb.on_rollout_start()
    assert model.gamma == model.rollout_buffer.gamma == vecnorm.gamma == pytest.approx(0.9703)
    for bad in ({"gamma_final": 0.98}, {"gamma_ramp": (1, 2)},
                {"gamma_final": 0.98, "gamma_ramp": (5, 2)}):  # fmt: skip
        with pytest.raises(ValueError, match="go together"):
            PPOConfig(**bad).validate()


def test_save_gif_keeps_every_frame_close_to_its_colours(tmp_path):
    """One shared palette: every frame is there, in order, within a few levels per channel."""
    from PIL import Image

    from training.plumbing.plots import save_gif

    frames = []
    for k in range(20):
        im = np.full((60, 80, 3), 255, np.uint8)
        im[10:30, 2 * k : 2 * k + 10] = (200, 30, 30)  # a red block moving right
        im[40:50, :] = (30, 30 + 5 * k, 200)  # a band changing colour
        frames.append(im)
    save_gif(frames, tmp_path / "a.gif", fps=50)
    with Image.open(tmp_path / "a.gif") as gif:
        assert gif.n_frames == 20
        for k in (0, 7, 19):
            gif.seek(k)
            err = np.abs(np.asarray(gif.convert("RGB"), int) - frames[k].astype(int))
            assert err.mean() < 2.0 and err.max() <= 64, (k, err.mean(), err.max())


@pytest.mark.parametrize("damage", ["narrower", "bfloat16"])
def test_a_start_whose_first_layer_cannot_be_widened_is_refused_in_one_line(tmp_path, damage):
    """Finding: --init-from with a narrower or bfloat16 first layer failed with a raw IndexError
    or TypeError before the weights were checked."""
    import shutil

    import torch
    from safetensors.torch import load_file, save_file

    from training.ppo.policy_io import open_snapshot, published_snapshot, write_manifest
    from training.ppo.widen import FIRST_LAYERS, widen_snapshot

    src = Path(__file__).resolve().parents[1] / "policies" / "ppo_gait_50hz"
    run = tmp_path / "start"
    shutil.copytree(src, run, ignore=shutil.ignore_patterns("figures"))
    which, _ = published_snapshot(run)
    path = run / which / "policy.safetensors"
    tensors = load_file(path)
    k = FIRST_LAYERS[0]
    tensors[k] = tensors[k][:, :-3] if damage == "narrower" else tensors[k].to(torch.bfloat16)
    save_file({n: t.contiguous() for n, t in tensors.items()}, path)
    write_manifest(path.parent)
    snap = open_snapshot(run, which)
    match = "reads 23 inputs where the start's observation has 26" if damage == "narrower" \
        else "bfloat16, not float32"  # fmt: skip
    with pytest.raises(ValueError, match=match) as e:
        widen_snapshot(snap, [26, 27], np.zeros(2), np.ones(2), width=26)
    assert "\n" not in str(e.value) and k in str(e.value)
