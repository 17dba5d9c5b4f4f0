"""Scripts and SB3 on the env with tiny budgets (smoke)."""

import json

import gymnasium as gym
import numpy as np

import biped_constraint_env  # noqa: F401
from training import open_loop


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


def test_sb3_ppo_learns_2048_steps(tmp_path):
    import torch
    from gymnasium.wrappers import RescaleAction
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    lo, hi = np.full(5, -1.0, np.float32), np.full(5, 1.0, np.float32)
    env = RescaleAction(gym.make("ConstrainedBiped-v0"), lo, hi)
    model = PPO("MlpPolicy", env, n_steps=512, batch_size=128, n_epochs=2, seed=0, device="cpu")
    model.learn(total_timesteps=2048)
    assert model.num_timesteps >= 2048
    model.save(tmp_path / "m.zip")
    assert (tmp_path / "m.zip").is_file()
