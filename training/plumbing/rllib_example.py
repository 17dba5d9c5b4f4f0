"""RLlib PPO on ConstrainedBiped-v0 with several env runners: the env in a distributed trainer.

    python -m training.plumbing.rllib_example [--iterations 5] [--env-runners 2]
        [--ray-address HOST:PORT]

A client of the environment, not a second training pipeline: RLlib builds the env in every
env-runner process from its registered id, ``"biped_constraint_env:ConstrainedBiped-v0"``
(Gymnasium imports the package, which registers the id, before ``gym.make``), with the default
walking task and nothing else of this project. The project's own PPO (imitation, then SB3 PPO)
is ``training.ppo.train``; this example shows that the env runs unchanged under RLlib's
sampling and learner processes, locally or on a cluster. It prints, per iteration, the env
steps sampled, the mean episode return and length, and the wall time.
"""

from __future__ import annotations

import argparse
import time

from training.plumbing.distributed import connect, shutdown

ENV = "biped_constraint_env:ConstrainedBiped-v0"


def build(env_runners: int, seed: int = 0, batch: int = 2000):
    """The RLlib PPO algorithm on the env (new API stack, torch, one thread per process)."""
    from ray.rllib.algorithms.ppo import PPOConfig

    config = (
        PPOConfig()
        .environment(ENV)
        .env_runners(num_env_runners=env_runners, num_envs_per_env_runner=1)
        .training(train_batch_size_per_learner=batch, minibatch_size=250, num_epochs=2)
        .debugging(seed=seed)
    )
    return config.build_algo()


def main(argv: list[str] | None = None) -> int:
    """Train a few iterations and print their results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--env-runners", type=int, default=2)
    ap.add_argument("--batch", type=int, default=2000, help="env steps per training iteration")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--ray-address", default="", help="HOST:PORT of a Ray cluster (else local)")
    a = ap.parse_args(argv)
    if a.iterations < 1 or a.env_runners < 1 or a.batch < 250:
        ap.error("need iterations >= 1, env-runners >= 1, batch >= 250")
    connect(True, a.ray_address)
    try:
        algo = build(a.env_runners, a.seed, a.batch)
        for it in range(a.iterations):
            t0 = time.time()
            result = algo.train()
            runners = result.get("env_runners", {})
            print(
                f"iteration {it}: {runners.get('num_env_steps_sampled_lifetime', 0)} env steps, "
                f"episode return {runners.get('episode_return_mean', float('nan')):.2f}, "
                f"length {runners.get('episode_len_mean', float('nan')):.1f} periods, "
                f"{time.time() - t0:.1f} s",
                flush=True,
            )
        algo.stop()
    finally:
        shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
