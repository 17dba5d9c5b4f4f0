"""The env's speed at this checkout and at another, side by side in alternating processes.

    git worktree add /tmp/base COMMIT
    python -m benchmarks.bench_ab --other /tmp/base [--rounds 3]
    python -m benchmarks.bench_ab --other /tmp/base --ppo training/configs/ppo_gait_50hz.toml \
        [--ppo-threads 2 2] [--ppo-steps 131072] [--rounds 3]

Each round runs one process per checkout (this one, then the other; ``PYTHONPATH`` picks the
checkout, one numba thread each) that times, after a warm-up: ``env.step`` on the exploration
workload (random torques at 5% of the bound, so that most periods end an episode and a reset
follows, as a random network's first rollouts do), the 256-row batched env on the same
workload, and ``env.step`` on the walking workload (the model controller's recorded actions
replayed from the same seed: no reset). Prints every round and the best of each (the
machine's slow spells only add time). A guardrail of the env's refactors: within 10% of the
commit before.

With ``--ppo CONFIG`` it times PPO instead, as ``python -m training.ppo.train --config CONFIG``
learns (:func:`benchmarks.bench_ppo.ppo_breakdown`, the same code run in each checkout's
process: the model and env as that checkout builds them): its env-steps/s with the env on
``--ppo-threads``' first number of numba threads and the updates on its second number of torch
threads, and where its wall time goes (the compiled period, the rest of the env, SB3's
wrappers, the rollout's network passes, the updates). Prints every round, the best of each and
the ratio of the best rates.
"""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from training.plumbing.common import CliParser, command, int_in

_TIMER = r"""
import json, time, numpy as np, gymnasium as gym
import biped_constraint_env
from training.controller.model_controller import controller_from

def single_random(n=20000):
    env = gym.make("ConstrainedBiped-v0")
    acts = np.random.default_rng(0).uniform(-7.5, 7.5, (n, 5))
    env.reset(seed=0); env.step(acts[0]); env.reset(seed=0)
    t0, k = time.perf_counter(), 0
    for a in acts:
        _, _, te, tr, _ = env.step(a)
        if te or tr:
            k += 1
            env.reset(seed=k)
    return (time.perf_counter() - t0) / n * 1e6

def batched_random(n=400, num=256):
    venv = gym.make_vec("ConstrainedBiped-v0", num, vectorization_mode="vector_entry_point")
    acts = np.random.default_rng(0).uniform(-7.5, 7.5, (n, num, 5))
    venv.reset(seed=0); venv.step(acts[0])
    t0 = time.perf_counter()
    for a in acts:
        venv.step(a)
    return n * num / (time.perf_counter() - t0)

def walking(n=3000):
    env = gym.make("ConstrainedBiped-v0")
    ctl = controller_from("model:teacher_robust")
    o, _ = env.reset(seed=0)
    acts = []
    for _ in range(n):
        a = ctl(o)
        acts.append(a)
        o, _, te, tr, _ = env.step(a)
        if te or tr:
            break
    env.reset(seed=0)
    t0 = time.perf_counter()
    for a in acts:
        env.step(a)
    return (time.perf_counter() - t0) / len(acts) * 1e6

print(json.dumps({"single_random_us": single_random(), "batched_random_steps_s": batched_random(),
                  "walking_us": walking()}))
"""


_PPO_TIMER = """
import json, sys
from training.plumbing.common import parse_config
from training.ppo.config import PPOConfig
{source}
config, steps, env_threads, update_threads = sys.argv[1], *map(int, sys.argv[2:5])
cfg = parse_config(PPOConfig, ["--config", config], "bench")
print(json.dumps(ppo_breakdown(cfg, steps, env_threads, update_threads)))
"""


def _time(checkout: Path, ppo: tuple | None = None) -> dict:
    """One timing process in ``checkout``: the env's rows, or PPO's (``ppo``: config, steps,
    env threads, update threads)."""
    env = {**os.environ, "PYTHONPATH": str(checkout),
           "NUMBA_NUM_THREADS": "1" if ppo is None else str(max(ppo[2], 1))}  # fmt: skip
    if ppo is None:
        cmd = [sys.executable, "-c", _TIMER]
    else:
        from benchmarks.bench_ppo import ppo_breakdown

        code = _PPO_TIMER.format(source=inspect.getsource(ppo_breakdown))
        cmd = [sys.executable, "-c", code, *map(str, ppo)]
    out = subprocess.run(cmd, cwd=checkout, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"bench_ab: the timing in {checkout} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _ppo_table(rows: dict, here: Path, other: Path) -> None:
    """The best rate of each checkout, its shares, and the ratio."""
    from benchmarks.bench_ppo import format_shares

    best = {name: max(rs, key=lambda r: r["rate"]) for name, rs in rows.items()}
    print("| checkout | PPO [env-steps/s] | where the wall time goes (its best round) |")
    print("|---|---|---|")
    for name, path in (("this", here), ("other", other)):
        b = best[name]
        print(f"| {name} ({path}) | {b['rate']:,.0f} | {format_shares(b['shares'])} |")
    print(f"this / other: {best['this']['rate'] / best['other']['rate']:.2f}x")
    digests = {r["sha256"] for rs in rows.values() for r in rs}
    print("the same numbers in both checkouts (weights and normaliser after the timed steps: "
          f"one SHA-256 in every round): {'yes' if len(digests) == 1 else 'no'} "
          f"({', '.join(sorted(d[:12] for d in digests))})")  # fmt: skip


@command("bench_ab")
def main(argv=None) -> int:
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("--other", type=Path, required=True, help="another checkout of the project")
    ap.add_argument("--rounds", type=int_in(1, 100), default=3, help="alternating rounds")
    ap.add_argument(
        "--ppo",
        default=None,
        metavar="CONFIG",
        help="time PPO with this train_ppo config instead of the env",
    )
    ap.add_argument(
        "--ppo-steps", type=int_in(4096, 10**8), default=131072, help="env steps per PPO timing"
    )
    ap.add_argument(
        "--ppo-threads",
        type=int_in(1, 64),
        nargs=2,
        default=(1, 2),
        metavar=("ENV", "UPDATES"),
        help="numba threads of the env, torch threads of the updates",
    )
    ap.add_argument("--other-ppo-threads", type=int_in(1, 64), nargs=2, default=None,
                    metavar=("ENV", "UPDATES"),
                    help="the other checkout's (default: --ppo-threads), e.g. to time each "
                         "checkout's README command")  # fmt: skip
    a = ap.parse_args(argv)
    here = Path(__file__).resolve().parents[1]
    if not (a.other / "biped_constraint_env" / "__init__.py").is_file():
        ap.error(f"--other {a.other}: not a checkout of this project")
    if a.ppo is not None and not (here / a.ppo).is_file():
        ap.error(f"--ppo {a.ppo}: no such config")
    ppo = None if a.ppo is None else (a.ppo, a.ppo_steps, *a.ppo_threads)
    other_threads = a.ppo_threads if a.other_ppo_threads is None else a.other_ppo_threads
    other_ppo = None if a.ppo is None else (a.ppo, a.ppo_steps, *other_threads)
    for checkout in (here, a.other):  # compile each checkout's core outside the timing
        _time(checkout)
    rows: dict[str, list[dict]] = {"this": [], "other": []}
    t0 = time.time()
    for k in range(a.rounds):
        for name, checkout, how in (("this", here, ppo), ("other", a.other, other_ppo)):
            rows[name].append(_time(checkout, how))
            print(f"round {k + 1} {name}: {json.dumps(rows[name][-1])} ({time.time() - t0:.0f} s)",
                  flush=True)  # fmt: skip
    if ppo is not None:
        print(
            f"PPO on {a.ppo}, {a.ppo_steps} env steps timed after one rollout; threads "
            f"(env, updates): this {tuple(a.ppo_threads)}, other {tuple(other_threads)}"
        )
        _ppo_table(rows, here, a.other)
        return 0
    best = {
        name: {
            "single_random_us": min(r["single_random_us"] for r in rs),
            "batched_random_steps_s": max(r["batched_random_steps_s"] for r in rs),
            "walking_us": min(r["walking_us"] for r in rs),
        }
        for name, rs in rows.items()
    }
    print("| checkout | env.step, exploration [us] | batched, exploration [env-steps/s] | "
          "env.step, walking [us] |")  # fmt: skip
    print("|---|---|---|---|")
    for name, b in best.items():
        print(f"| {name} | {b['single_random_us']:.1f} | {b['batched_random_steps_s']:,.0f} | "
              f"{b['walking_us']:.2f} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
