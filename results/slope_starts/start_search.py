"""Can the rest start on +5 deg be made at all? A search for an opening on top of the network.

    python results/slope_starts/start_search.py POLICY OUT.json [--slope-deg 5] [--generations 60]

From the paper's rest posture on a slope rising forward, the published command policy's first
step fails (``slope_starts.py``). This searches (CMA-ES, the ``cma`` package) a feed-forward
torque added to the network's own torques during the first ``--span-s`` seconds (piecewise
linear through ``--knots`` knots per joint, clipped with the sum to 150 N m; zero after), the
network alone after that, commanded 1.0 m/s, under the default strict physics. Every row of
one batched env runs one candidate from the same start (the same seed: the same reset noise);
a candidate's cost is minus the steps it completes in ``--horizon-s`` seconds and the time it
lasted. The best candidate is then run for 30 s from the same start: a start is made when it
completes at least 20 steps there (the protocol's walking success). The search starts at zero
(the network's own failing start). Development seeds (700000+).
"""

import argparse
import json
import math
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

import biped_constraint_env  # noqa: F401
from training.plumbing.stats import MIN_STEPS
from training.plumbing.outputs import write_file
from training.ppo.policy_io import load_policy, policy_batch_actor

PERIOD_S = 0.02
LIMIT = 150.0


def run(act, kw, seed, ff, span_s, horizon_s):
    """Steps completed and time lasted per row of ``ff`` (n, 5, K) [N m] from one start."""
    n, _, k = ff.shape
    venv = gym.make_vec("ConstrainedBiped-v0", num_envs=n, vectorization_mode="vector_entry_point",
                        **{**kw, "termination": {"time_limit_s": horizon_s}})  # fmt: skip
    obs, info = venv.reset(seed=[seed] * n, options={"command": 1.0})
    alive = np.ones(n, bool)
    lasted = np.full(n, horizon_s)
    steps = np.zeros(n, int)
    for i in range(int(round(horizon_s / PERIOD_S))):
        t = i * PERIOD_S
        tau = np.asarray(act(obs), dtype=np.float64)
        if t < span_s:
            u = t / span_s * (k - 1)
            j = min(int(u), k - 2)
            w = u - j
            tau = tau + (1 - w) * ff[:, :, j] + w * ff[:, :, j + 1]
        tau = np.clip(tau, -LIMIT, LIMIT)
        tau[~alive] = 0.0
        obs, _, te, tr, info = venv.step(tau)
        steps = np.where(alive, info["steps_completed"], steps)
        ended = (te | tr) & alive
        lasted[ended & ~tr] = (i + 1) * PERIOD_S
        alive &= ~(te | tr)
        if not alive.any():
            break
    venv.close()
    return steps, lasted


def main():
    """Search each start's opening; write the JSON."""
    import cma

    p = argparse.ArgumentParser()
    p.add_argument("policy", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--slope-deg", type=float, default=5.0)
    p.add_argument("--seeds", type=int, nargs="+", default=[700000, 700001, 700002])
    p.add_argument("--generations", type=int, default=60)
    p.add_argument("--popsize", type=int, default=32)
    p.add_argument("--knots", type=int, default=6)
    p.add_argument("--span-s", type=float, default=1.5)
    p.add_argument("--horizon-s", type=float, default=8.0)
    p.add_argument("--sigma-nm", type=float, default=15.0)
    a = p.parse_args()
    torch.set_num_threads(1)
    policy, norm, cfg, _ = load_policy(a.policy)
    act = policy_batch_actor(policy, norm, cfg)
    kw = {**cfg.env_kwargs(), "start": "rest",
          "perturbations": {"slope_rad": math.radians(a.slope_deg)}}  # fmt: skip
    out = []
    for seed in a.seeds:
        t0 = time.time()
        opts = {"popsize": a.popsize, "seed": seed, "verbose": -9}
        es = cma.CMAEvolutionStrategy(np.zeros(5 * a.knots), a.sigma_nm, opts)
        best, history = (math.inf, None), []
        for g in range(a.generations):
            x = np.array(es.ask())
            steps, lasted = run(act, kw, seed, x.reshape(-1, 5, a.knots), a.span_s, a.horizon_s)
            cost = -steps - lasted / a.horizon_s
            es.tell(list(x), cost.tolist())
            i = int(np.argmin(cost))
            if cost[i] < best[0]:
                best = (float(cost[i]), x[i].copy())
            history.append([int(steps.max()), float(lasted.max())])
            print(f"seed {seed} gen {g}: most steps {steps.max()}, longest {lasted.max():.2f} s",
                  flush=True)  # fmt: skip
        ff = best[1].reshape(1, 5, a.knots)
        steps30, lasted30 = run(act, kw, seed, ff, a.span_s, 30.0)
        made = bool(steps30[0] >= MIN_STEPS)
        zero = run(act, kw, seed, np.zeros((1, 5, a.knots)), a.span_s, 30.0)
        out.append({"seed": seed, "made": made, "steps_30s": int(steps30[0]),
                    "lasted_30s": float(lasted30[0]), "network_alone_steps_30s": int(zero[0][0]),
                    "network_alone_lasted_s": float(zero[1][0]),
                    "best_ff_nm": best[1].reshape(5, a.knots).round(2).tolist(),
                    "max_abs_ff_nm": float(np.abs(best[1]).max()),
                    "per_generation_most_steps_longest_s": history,
                    "wall_s": round(time.time() - t0, 1)})  # fmt: skip
        print(json.dumps({k: v for k, v in out[-1].items()
                          if k not in ("best_ff_nm", "per_generation_most_steps_longest_s")}),
              flush=True)  # fmt: skip
    write_file(a.out, json.dumps({"policy": str(a.policy), "args": {k: str(v) for k, v in
                                 vars(a).items()}, "starts": out}, indent=1) + "\n")  # fmt: skip


if __name__ == "__main__":
    main()
