"""Plain Stable-Baselines3 PPO learns to walk with no recorded motion (docs/sb3.md).

    python examples/train_sb3.py [SEED [ENV_STEPS]]    (--help: the options)

The network alone sets the five joint torques every 20 ms; the reward is the task and the
contact clock (``reward={"kind": "gait", ...}``), the training starts are the env's own
(``start={"stride": 0.75, "midstride": 0.25}``) and a contact phase held over 1 s ends a
training episode. SB3's ``PPO``, ``VecNormalize``, ``EvalCallback`` and ``CheckpointCallback``
(model and normaliser every 100k env steps) do the rest, with two small callbacks: the
discount's ramp and the normaliser saved with the best model. Ctrl-C saves the model and the
normaliser as they are and stops.
"""

import argparse
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import (
    BaseCallback,
    CallbackList,
    CheckpointCallback,
    EvalCallback,
)
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from training.plumbing.rollouts import run_episodes_batched
from training.plumbing.stats import format_success, success
from training.ppo.sb3_vec import make_sb3_vec_env

DT = 0.02  # the control period [s]: the paper's sample time
GAIT = {  # the env the policy runs in: no reference anywhere
    "dt": DT,
    "action": "torque",
    "observation": ["phase"],  # the contact clock in the input
    "reward": {"kind": "gait", "gated": True, "weights": {"step": 10.0},
               "kernels": {"cadence": 50.0}, "targets": {"cadence": [0.6, 0.25, 0.15, 0.1]}},
}  # fmt: skip
TRAIN = {**GAIT, "start": {"stride": 0.75, "midstride": 0.25},
         "termination": {"max_model_time_s": 1.0}}  # fmt: skip
EVAL = {**GAIT, "start": "midstride"}  # the env's own start, strict physics
EVAL_S = 120.0  # the evaluations' episodes [s]: a walk that lasts them all is selected
GEAR = 150.0  # N m per unit action (make_sb3_vec_env's default)
N_ENVS = 64
CHECKPOINT_EVERY = 100_000  # env steps between checkpoints (model and normaliser)


class GammaRamp(BaseCallback):
    """The discount: 0.9606 (0.5 s) while the start is learned, then 0.98 (1 s) over 1M-3M."""

    def __init__(self, normaliser, start=0.9606, final=0.98, ramp=(1_000_000, 3_000_000)):
        super().__init__()
        self.normaliser, self.start, self.final, self.ramp = normaliser, start, final, ramp

    def _on_rollout_start(self) -> None:
        a, b = self.ramp
        f = min(max((self.model.num_timesteps - a) / (b - a), 0.0), 1.0)
        g = self.start + f * (self.final - self.start)
        self.model.gamma = self.model.rollout_buffer.gamma = self.normaliser.gamma = g
        self.logger.record("train/gamma", g)

    def _on_step(self) -> bool:
        return True


class SaveNormaliser(BaseCallback):
    """On a new best: the training normaliser beside ``best_model.zip`` (they belong together)."""

    def __init__(self, normaliser, path):
        super().__init__()
        self.normaliser, self.path = normaliser, path

    def _on_step(self) -> bool:
        self.normaliser.save(str(self.path))
        return True


class StopWhenEveryEpisodeLasts(BaseCallback):
    """Stop once every evaluation episode lasted its full time in ``evals`` evaluations in a row."""

    def __init__(self, evals=2):
        super().__init__()
        self.evals, self.row = evals, 0

    def _on_step(self) -> bool:
        lengths = self.parent.evaluations_length[-1]
        self.row = self.row + 1 if min(lengths) >= round(EVAL_S / DT) else 0
        return self.row < self.evals


def train(
    seed=0,
    total_timesteps=12_000_000,
    out="runs/sb3_example",
    progress_bar=True,
    eval_every=500_000,
):
    """PPO from a random network; returns (the best model, its normaliser).

    Every ``eval_every`` env steps, 30 mid-stride episodes of 120 s (``evaluations.npz``).
    """
    torch.set_num_threads(1)  # the batched env takes the other core
    out = Path(out)
    env = make_sb3_vec_env(N_ENVS, seed, TRAIN, max_episode_steps=round(5 / DT))  # 5 s episodes
    env = VecNormalize(VecMonitor(env, str(out / "monitor.csv")), gamma=0.9606)
    evals = make_sb3_vec_env(10, seed + 1, {**EVAL, "termination": {"time_limit_s": EVAL_S}},
                             max_episode_steps=round(EVAL_S / DT))  # fmt: skip
    evals = VecNormalize(VecMonitor(evals), training=False, norm_reward=False)  # same wrappers
    model = PPO(
        "MlpPolicy", env, n_steps=64, batch_size=1024, n_epochs=5, seed=seed, device="cpu",
        gamma=0.9606, learning_rate=LinearSchedule(3e-4, 0.0, 1.0), tensorboard_log=str(out),
        policy_kwargs={"net_arch": [128, 128]},
    )  # fmt: skip
    model.policy.log_std.data[:] = torch.tensor([-5.0, -4.0, -4.0, -3.5, -3.0])  # per joint
    # the initial action mean: +12 N m at the stance ankle, which the mid-stride start needs
    model.policy.action_net.bias.data[:] = torch.tensor([12.0, 0, 0, 0, 0]) / GEAR
    best = EvalCallback(
        evals, n_eval_episodes=30, eval_freq=eval_every // 64,
        log_path=str(out), best_model_save_path=str(out),
        callback_on_new_best=SaveNormaliser(env, out / "vecnormalize.pkl"),
        callback_after_eval=StopWhenEveryEpisodeLasts(), deterministic=True, verbose=1,
    )  # fmt: skip
    checkpoints = CheckpointCallback(CHECKPOINT_EVERY // N_ENVS, str(out / "checkpoints"),
                                     save_vecnormalize=True)  # fmt: skip
    try:
        model.learn(total_timesteps, callback=CallbackList([GammaRamp(env), best, checkpoints]),
                    progress_bar=progress_bar)  # fmt: skip
    except KeyboardInterrupt:  # Ctrl-C: keep what was learned so far, then stop
        model.save(out / "interrupted_model.zip")
        env.save(str(out / "interrupted_vecnormalize.pkl"))
        env.close()
        raise KeyboardInterrupt(
            f"interrupted at {model.num_timesteps} env steps: saved {out}/interrupted_model.zip "
            f"and {out}/interrupted_vecnormalize.pkl"
        ) from None
    if not (out / "best_model.zip").is_file():  # a budget shorter than one evaluation
        model.save(out / "best_model.zip")
        env.save(str(out / "vecnormalize.pkl"))
    env.close()  # the monitor file
    model.logger.close()  # the TensorBoard writer
    model = PPO.load(out / "best_model.zip", device="cpu")
    normaliser = VecNormalize.load(str(out / "vecnormalize.pkl"), evals)
    normaliser.training = False  # for evaluation: its statistics stay as saved
    return model, normaliser


def evaluate(model, normaliser, episodes=200, first_seed=500_000) -> dict:
    """Success (>= 20 complete strict steps in 30 s) of the deterministic policy, mid-stride."""

    def act(obs):
        return np.clip(model.predict(normaliser.normalize_obs(obs), deterministic=True)[0],
                       -1.0, 1.0) * GEAR  # fmt: skip

    eps = run_episodes_batched(act, EVAL, range(first_seed, first_seed + episodes))
    return success([e["steps_completed"] for e in eps])


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", nargs="?", type=int, default=0, help="training seed (default 0)")
    ap.add_argument("env_steps", nargs="?", type=int, default=12_000_000,
                    help="env steps at most (default 12M; it stops once it walks)")  # fmt: skip
    a = ap.parse_args()
    if a.env_steps < 1:
        ap.error("env_steps must be at least 1")
    out = Path("runs") / f"sb3_example_seed{a.seed}"
    print(f"curves: tensorboard --logdir {out} (and {out}/monitor.csv)")
    try:
        model, normaliser = train(a.seed, a.env_steps, out)
    except KeyboardInterrupt as e:
        raise SystemExit(str(e) or "interrupted") from None
    print(f"saved {out}/best_model.zip and {out}/vecnormalize.pkl")
    print("success (>= 20 steps in 30 s), 95% CI:", format_success(evaluate(model, normaliser)))
