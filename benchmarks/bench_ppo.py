"""PPO's training throughput on the batched env, side by side with the env alone, in one run.

    python -m benchmarks.bench_ppo [--config training/configs/ppo_from_scratch.toml]
                                   [--steps 200000] [--rounds 2] [TRAIN_PPO FLAGS ...]

Stable-Baselines3 PPO, built exactly as ``python -m training.ppo.train --config CONFIG`` builds
it (the config's env options, network, rollout, minibatch, epochs; VecMonitor and
VecNormalize; the batched env behind :class:`training.ppo.sb3_vec.BatchedSB3VecEnv`), learns for
``--steps`` env steps after a warm-up update; its env-steps/s include rollouts and updates (a
config with a teacher is timed in its PPO phase, from a fresh network: the imitation before it
is not PPO). Any further flag is a ``train_ppo`` flag that overrides the config (e.g.
``--net-arch 64 64 --n-envs 128 --n-steps 32``), as on train_ppo's command line.
Rows:

* PPO with the batched env on one numba thread and torch on one thread throughout (the
  setting for two training processes on 2 cores);
* the same with torch on two threads in the updates only (``update_threads = 2``: the env is
  idle then), the setting for one training process on 2 cores;
* PPO with the env on two numba threads next to torch on one (the oversubscription the
  one-thread default avoids), and the same with torch on two threads in the updates: one
  training process alone on 2 cores with ``--env-threads 2 --update-threads 2`` (the batched
  env's rows split between two threads give the same numbers as one thread);
* two PPO processes side by side (two training seeds at once, as ``training.ppo.sweep`` or two
  shells run them), each on one env and one torch thread: the sum of their rates;
* the batched env alone on one thread, stepped with actions drawn as the config's initial
  policy draws them (Gaussian about 0 with its initial std, clipped).

Each figure is the best of ``--rounds`` interleaved rounds. Early in training most episodes
are short, so these rows include many resets, as a real run's first minutes do. Three PPO rows
also say where their wall time goes (:data:`PARTS`, :func:`ppo_breakdown`);
``benchmarks.bench_ab --ppo CONFIG`` times the same against another checkout.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import numpy as np

DEFAULT_CONFIG = "training/configs/ppo_from_scratch.toml"


def _config(path: str, overrides: Sequence[str] = ()):
    """The PPOConfig of a train_ppo config file with train_ppo flags on top."""
    from training.plumbing.common import parse_config
    from training.ppo.config import PPOConfig

    return parse_config(PPOConfig, ["--config", path, *overrides], "bench")


SHARES: dict[str, dict[str, float]] = {}
"""The last timing's shares of its wall time (:data:`PARTS`), by row."""

PARTS = ("physics", "env", "wrappers", "rollout", "updates")
"""Where PPO's wall time goes: the compiled period (``physics``: dynamics, events, the compiled
observation and reward record); the rest of the batched env's step and resets (``env``: the
Python and numpy parts, the SB3 VecEnv adapter); SB3's VecMonitor and VecNormalize
(``wrappers``); the rollout's network passes, buffer and callbacks (``rollout``: the rest of the
rollouts); PPO's updates (``updates``: ``model.train``)."""


def ppo_breakdown(cfg, steps: int, env_threads: int, update_threads: int, barrier=None,
                  seed: int = 0) -> dict:  # fmt: skip
    """Env steps per second of PPO.learn on the batched env, and where its wall time goes.

    Builds the model as ``training.ppo.train`` does (``make_model``, ``training_env``), learns
    one rollout as a warm-up, then ``steps`` env steps timed; returns ``{"rate": env-steps/s,
    "shares": {part: share of the wall time}, "sha256": the digest of the weights and the
    normaliser's statistics at the end}`` (:data:`PARTS`; the same config, seed, threads and
    steps in two checkouts give the same digest where they compute the same numbers).
    Self-contained: it uses only what every checkout of the project has, so
    ``benchmarks.bench_ab`` runs it on another.
    ``barrier``: a multiprocessing barrier that the timed learning waits on after the warm-up
    (two processes side by side start timing together).
    """
    import hashlib as _hashlib
    import tempfile as _tempfile
    import time as _time
    from pathlib import Path as _Path

    import torch

    from training.ppo.build import make_model, training_env
    from training.ppo.callbacks import update_threads as threads_callback

    torch.set_num_threads(1)
    venv, vecnorm = training_env(cfg, seed, env_threads=env_threads)
    with _tempfile.TemporaryDirectory() as tmp:
        model = make_model(cfg, vecnorm, _Path(tmp))
        callback = threads_callback(1, update_threads)
        model.learn(total_timesteps=cfg.n_envs * cfg.n_steps, callback=callback)  # warm-up
        if barrier is not None:
            barrier.wait()
        spent = dict.fromkeys(("physics", "inner", "outer", "updates"), 0.0)
        inner = venv.venv  # the SB3 adapter of the batched env, under the VecMonitor
        buf = inner.venv.core.buf

        def timed(what, fn):
            def run(*args, **kwargs):
                t = _time.perf_counter()
                try:
                    return fn(*args, **kwargs)
                finally:
                    spent[what] += _time.perf_counter() - t

            return run

        buf.period = timed("physics", buf.period)
        inner.step_wait = timed("inner", inner.step_wait)
        vecnorm.step_wait = timed("outer", vecnorm.step_wait)
        model.train = timed("updates", model.train)
        t0 = _time.perf_counter()
        model.learn(total_timesteps=steps, reset_num_timesteps=False, callback=callback)
        wall = _time.perf_counter() - t0
    digest = _hashlib.sha256()  # what the run computed: its weights and normaliser
    for value in model.policy.state_dict().values():
        digest.update(value.detach().numpy().tobytes())
    for rms in (vecnorm.obs_rms, vecnorm.ret_rms):
        digest.update(rms.mean.tobytes() + rms.var.tobytes())
    torch.set_num_threads(1)
    venv.close()
    parts = {"physics": spent["physics"], "env": spent["inner"] - spent["physics"],
             "wrappers": spent["outer"] - spent["inner"], "updates": spent["updates"]}  # fmt: skip
    parts["rollout"] = wall - sum(parts.values())
    order = ("physics", "env", "wrappers", "rollout", "updates")  # PARTS (self-contained)
    return {"rate": steps / wall, "shares": {k: parts[k] / wall for k in order},
            "sha256": digest.hexdigest()}  # fmt: skip


def ppo_steps_per_s(
    cfg, steps: int, env_threads: int, update_threads: int, barrier=None, seed: int = 0,
    shares: str | None = None,
) -> float:  # fmt: skip
    """Env steps per second of PPO.learn on the batched env (rollouts and updates).

    :func:`ppo_breakdown`'s rate; ``shares``: a row name under which its shares of the wall
    time go to :data:`SHARES`.
    """
    out = ppo_breakdown(cfg, steps, env_threads, update_threads, barrier, seed)
    if shares is not None:
        SHARES[shares] = out["shares"]
    return out["rate"]


def format_shares(share: dict) -> str:
    """The shares of a PPO timing's wall time in words."""
    return ("of its wall time: " + ", ".join(f"{k} {share[k]:.0%}" for k in PARTS)
            + f"; the env in all {share['physics'] + share['env']:.0%}")  # fmt: skip


def _side_by_side_worker(config: str, overrides, steps: int, seed: int, barrier, out) -> None:
    out.put(ppo_steps_per_s(_config(config, overrides), steps, 1, 1, barrier, seed))


def two_ppo_steps_per_s(config: str, steps: int, overrides: Sequence[str] = ()) -> float:
    """Total env steps per second of two PPO processes side by side (e.g. two seeds at once),
    each with the env and torch on one thread: the sum of their rates, timed together."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    barrier, out = ctx.Barrier(2), ctx.Queue()
    procs = [
        ctx.Process(
            target=_side_by_side_worker, args=(config, list(overrides), steps, seed, barrier, out)
        )
        for seed in (0, 1)
    ]
    for p in procs:
        p.start()
    rates = [out.get() for _ in procs]
    for p in procs:
        p.join()
    return sum(rates)


def env_steps_per_s(cfg, steps: int, env_threads: int) -> float:
    """Env steps per second of the same batched env alone, with the initial policy's law."""
    from training.ppo.sb3_vec import make_sb3_vec_env

    venv = make_sb3_vec_env(
        cfg.n_envs, 0, cfg.train_env_kwargs(), "batched", cfg.env_id, cfg.action_map(),
        num_threads=env_threads, max_episode_steps=cfg.train_max_episode_steps(),
    )  # fmt: skip
    venv.reset()
    rng = np.random.default_rng(0)
    n = max(steps // cfg.n_envs, 1)
    std = float(np.exp(cfg.log_std_init))
    acts = np.clip(std * rng.standard_normal((n, cfg.n_envs, 5)), -1, 1).astype(np.float32)
    t0 = time.perf_counter()
    for a in acts:
        venv.step(a)
    rate = n * cfg.n_envs / (time.perf_counter() - t0)
    venv.close()
    return rate


def main(argv=None) -> int:
    """Time PPO and the env alone; print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=DEFAULT_CONFIG, help="a train_ppo config (TOML)")
    ap.add_argument("--steps", type=int, default=200_000, help="env steps per PPO timing")
    ap.add_argument("--rounds", type=int, default=2)
    a, overrides = ap.parse_known_args(argv)
    cfg = _config(a.config, overrides)
    rows = {
        "PPO, env 1 thread, torch 1 thread": lambda: ppo_steps_per_s(
            cfg, a.steps, 1, 1, shares="PPO, env 1 thread, torch 1 thread"
        ),
        "PPO, env 1 thread, torch 1 thread (2 in updates)": lambda: ppo_steps_per_s(
            cfg, a.steps, 1, 2, shares="PPO, env 1 thread, torch 1 thread (2 in updates)"
        ),
        "PPO, env 2 threads, torch 1 thread": lambda: ppo_steps_per_s(cfg, a.steps, 2, 1),
        "PPO, env 2 threads, torch 1 thread (2 in updates)": lambda: ppo_steps_per_s(
            cfg, a.steps, 2, 2, shares="PPO, env 2 threads, torch 1 thread (2 in updates)"
        ),
        "two PPO processes side by side, 1 + 1 threads each, in total": lambda: two_ppo_steps_per_s(
            a.config, a.steps, overrides
        ),
        "the batched env alone, 1 thread": lambda: env_steps_per_s(cfg, a.steps, 1),
    }
    best: dict[str, float] = {}
    for r in range(a.rounds):
        for key, fn in rows.items():
            rate = fn()
            best[key] = max(best.get(key, 0.0), rate)
            print(f"round {r + 1}/{a.rounds}: {key}: {rate:,.0f} env-steps/s", flush=True)
    print(
        f"{' '.join([a.config, *overrides])}: {cfg.n_envs} envs x {cfg.n_steps} steps, "
        f"minibatch {cfg.batch_size}, {cfg.n_epochs} epochs, net {list(cfg.net_arch)} "
        f"{cfg.activation}; best of {a.rounds} rounds:"
    )
    for key, rate in best.items():
        share = SHARES.get(key)
        extra = "" if share is None else f" ({format_shares(share)}; last round)"
        print(f"{key}: {rate:,.0f} env-steps/s{extra}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
