"""The env's speed at this checkout and at another, side by side in alternating processes.

    git worktree add /tmp/base COMMIT
    python -m benchmarks.bench_ab --other /tmp/base [--rounds 3]

Each round runs one process per checkout (this one, then the other; ``PYTHONPATH`` picks the
checkout, one numba thread each) that times, after a warm-up: ``env.step`` on the exploration
workload (random torques at 5% of the bound, so that most periods end an episode and a reset
follows, as a random network's first rollouts do), the 256-row batched env on the same
workload, and ``env.step`` on the walking workload (the model controller's recorded actions
replayed from the same seed: no reset). Prints every round and the best of each (the
machine's slow spells only add time). A guardrail of the env's refactors: within 10% of the
commit before.
"""

from __future__ import annotations

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


def _time(checkout: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(checkout), "NUMBA_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _TIMER], cwd=checkout, env=env,
                         capture_output=True, text=True, check=True)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


@command("bench_ab")
def main(argv=None) -> int:
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("--other", type=Path, required=True, help="another checkout of the project")
    ap.add_argument("--rounds", type=int_in(1, 100), default=3, help="alternating rounds")
    a = ap.parse_args(argv)
    here = Path(__file__).resolve().parents[1]
    if not (a.other / "biped_constraint_env" / "__init__.py").is_file():
        ap.error(f"--other {a.other}: not a checkout of this project")
    for checkout in (here, a.other):  # compile each checkout's core outside the timing
        _time(checkout)
    rows: dict[str, list[dict]] = {"this": [], "other": []}
    t0 = time.time()
    for k in range(a.rounds):
        for name, checkout in (("this", here), ("other", a.other)):
            rows[name].append(_time(checkout))
            print(f"round {k + 1} {name}: {json.dumps(rows[name][-1])} ({time.time() - t0:.0f} s)",
                  flush=True)  # fmt: skip
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
