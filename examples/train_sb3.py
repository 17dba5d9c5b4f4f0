"""Plain Stable-Baselines3 PPO on ConstrainedBiped-v0's tracking task (docs/sb3.md)."""

import sys

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from training.rollouts import run_episodes_batched
from training.sb3_vec import make_sb3_vec_env
from training.stats import format_success, success


def train(total_timesteps: int = 12_000_000, seed: int = 0, progress_bar: bool = True):
    """PPO from a random network on the track task; returns (model, its VecNormalize env)."""
    torch.set_num_threads(1)  # the batched env takes the other core
    env = make_sb3_vec_env(64, seed, {"task": "track"}, max_episode_steps=1000)  # 5 s episodes
    env = VecNormalize(VecMonitor(env), gamma=0.99)
    model = PPO(
        "MlpPolicy", env, n_steps=64, batch_size=1024, n_epochs=5, seed=seed, device="cpu",
        learning_rate=LinearSchedule(3e-4, 0.0, 1.0), policy_kwargs={"net_arch": [128, 128]},
    )  # fmt: skip
    model.policy.log_std.data[:] = torch.tensor([-5.0, -4.0, -4.0, -3.5, -3.0])  # per joint
    model.learn(total_timesteps, progress_bar=progress_bar)
    return model, env


def evaluate(model, env, episodes: int = 200, first_seed: int = 500_000) -> dict:
    """Success (>= 20 complete steps in 30 s) of the deterministic policy, mid-stride starts."""

    def act(obs):
        return model.predict(env.normalize_obs(obs), deterministic=True)[0]

    seeds = range(first_seed, first_seed + episodes)  # the report seeds; no reference starts
    eps = run_episodes_batched(act, {"task": "track", "rsi": 0.0}, seeds)
    return success([e["steps_completed"] for e in eps])


if __name__ == "__main__":  # python examples/train_sb3.py [ENV_STEPS [SEED]]
    steps = int(sys.argv[1]) if len(sys.argv) > 1 else 12_000_000
    model, env = train(steps, seed=int(sys.argv[2]) if len(sys.argv) > 2 else 0)
    print("success (>= 20 steps in 30 s), 95% CI:", format_success(evaluate(model, env)))
