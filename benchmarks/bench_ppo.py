"""PPO's training throughput on the batched env, side by side with the env alone, in one run.

    python -m benchmarks.bench_ppo [--steps 200000] [--n-envs 64] [--n-steps 64]

Stable-Baselines3 PPO (MlpPolicy 128 x 128, 5 epochs, minibatch 1024, one torch thread) learns
on the batched env through :class:`training.sb3_vec.BatchedSB3VecEnv` (the walking task,
default physics, actions in [-1, 1] scaled by 150 N m) for ``--steps`` env steps; its
env-steps/s include rollouts and updates. Beside it, the same batched env alone, stepped with
actions drawn as PPO's initial policy draws them (Gaussian, std 1, clipped). Both are timed
with the batched env on one numba thread (the default: ``num_threads=1``) and on two, to show
what the thread policy does next to torch on this machine. Each figure is the best of
``--rounds`` interleaved rounds.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def ppo_steps_per_s(n_envs: int, n_steps: int, steps: int, env_threads: int) -> float:
    """Env steps per second of PPO.learn on the batched env (rollouts and updates)."""
    import torch
    from stable_baselines3 import PPO

    from training.sb3_vec import make_sb3_vec_env

    torch.set_num_threads(1)
    venv = make_sb3_vec_env(n_envs, 0, {}, "batched", num_threads=env_threads)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=n_steps,
        batch_size=1024,
        n_epochs=5,
        policy_kwargs={"net_arch": [128, 128]},
        seed=0,
        device="cpu",
        verbose=0,
    )
    model.learn(total_timesteps=n_envs * n_steps)  # warm-up: first compile, first update
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False)
    rate = steps / (time.perf_counter() - t0)
    venv.close()
    return rate


def env_steps_per_s(n_envs: int, steps: int, env_threads: int) -> float:
    """Env steps per second of the same batched env alone, with PPO's initial action law."""
    from training.sb3_vec import make_sb3_vec_env

    venv = make_sb3_vec_env(n_envs, 0, {}, "batched", num_threads=env_threads)
    venv.reset()
    rng = np.random.default_rng(0)
    n = max(steps // n_envs, 1)
    acts = np.clip(rng.standard_normal((n, n_envs, 5)), -1, 1).astype(np.float32)
    t0 = time.perf_counter()
    for a in acts:
        venv.step(a)
    rate = n * n_envs / (time.perf_counter() - t0)
    venv.close()
    return rate


def main(argv=None) -> int:
    """Time PPO and the env alone at 1 and 2 env threads; print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200_000, help="env steps per PPO timing")
    ap.add_argument("--n-envs", type=int, default=64)
    ap.add_argument("--n-steps", type=int, default=64, help="PPO rollout length per env")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    best: dict[str, float] = {}
    for r in range(a.rounds):
        for threads in (1, 2):
            for label, fn in (
                ("PPO (rollouts + updates)", lambda t=threads: ppo_steps_per_s(
                    a.n_envs, a.n_steps, a.steps, t)),
                ("the batched env alone", lambda t=threads: env_steps_per_s(
                    a.n_envs, a.steps, t)),
            ):  # fmt: skip
                key = f"{label}, env on {threads} thread{'s' if threads > 1 else ''}"
                best[key] = max(best.get(key, 0.0), fn())
        print(f"round {r + 1}/{a.rounds} done", flush=True)
    print(f"best of {a.rounds} rounds, {a.n_envs} envs, torch on 1 thread:")
    for key, rate in best.items():
        print(f"{key}: {rate:,.0f} env-steps/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
