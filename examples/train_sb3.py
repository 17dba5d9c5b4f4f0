"""Plain Stable-Baselines3 PPO on ConstrainedBiped-v0's tracking task (docs/sb3.md)."""

import sys
from pathlib import Path

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from training.evaluation.rollouts import run_episodes_batched
from training.evaluation.stats import format_success, success
from training.ppo.sb3_vec import make_sb3_vec_env


def train(total_timesteps=12_000_000, seed=0, dt=0.005, progress_bar=True, log_dir=None):
    """PPO from a random network on the track task; returns (model, its VecNormalize env).

    ``dt``: the control period [s]; the PD targets hold over it, the PD law runs every 5 ms.
    ``log_dir``: where the curves go (episode returns in ``monitor.csv``, SB3's losses and
    rollout means for TensorBoard), or None.
    """
    torch.set_num_threads(1)  # the batched env takes the other core
    kw = {"task": "track", "dt": dt}
    env = make_sb3_vec_env(64, seed, kw, max_episode_steps=round(5 / dt))  # 5 s episodes
    gamma = 0.99 ** (dt / 0.005)  # the same horizon in seconds at any control period
    monitor = None if log_dir is None else str(Path(log_dir) / "monitor.csv")
    env = VecNormalize(VecMonitor(env, monitor), gamma=gamma)
    model = PPO(
        "MlpPolicy", env, n_steps=64, batch_size=1024, n_epochs=5, seed=seed, device="cpu",
        gamma=gamma, tensorboard_log=None if log_dir is None else str(log_dir),
        learning_rate=LinearSchedule(3e-4, 0.0, 1.0), policy_kwargs={"net_arch": [128, 128]},
    )  # fmt: skip
    model.policy.log_std.data[:] = torch.tensor([-5.0, -4.0, -4.0, -3.5, -3.0])  # per joint
    model.learn(total_timesteps, progress_bar=progress_bar)
    return model, env


def evaluate(model, env, dt=0.005, episodes=200, first_seed=500_000) -> dict:
    """Success (>= 20 complete steps in 30 s) of the deterministic policy, mid-stride starts."""

    def act(obs):
        return model.predict(env.normalize_obs(obs), deterministic=True)[0]

    seeds = range(first_seed, first_seed + episodes)  # the report seeds; no reference starts
    kw = {"task": "track", "start": "midstride", "dt": dt}  # 30 s episodes (the env's time limit)
    eps = run_episodes_batched(act, kw, seeds)
    return success([e["steps_completed"] for e in eps])


def save(model, env, out) -> None:
    """The trained model and its normaliser, as SB3 saves them (SB3's own pickles)."""
    Path(out).mkdir(parents=True, exist_ok=True)
    model.save(Path(out) / "model.zip")
    env.save(str(Path(out) / "vecnormalize.pkl"))


if __name__ == "__main__":  # python examples/train_sb3.py [ENV_STEPS [SEED [DT]]]
    args = sys.argv[1:] + ["12000000", "0", "0.005"][len(sys.argv) - 1 :]
    steps, seed, dt = int(args[0]), int(args[1]), float(args[2])
    out = Path("runs") / f"sb3_example_seed{seed}"
    print(f"curves: tensorboard --logdir {out} (and {out}/monitor.csv)")
    model, env = train(steps, seed, dt, log_dir=out)
    save(model, env, out)
    print(f"saved {out}/model.zip and {out}/vecnormalize.pkl")
    print("success (>= 20 steps in 30 s), 95% CI:", format_success(evaluate(model, env, dt)))
