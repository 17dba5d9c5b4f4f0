"""The stop row and the zero-command check from the brake and stand starts, on development seeds.

python brake_check.py RUN {best,final,checkpoint} [N] -> stdout: the protocol's stop and restart
rows on N development episodes (seeds 700000+, default 30; 0: none), then 20 episodes each from
the "brake" start (model 4 moving forward at 0-0.8 m/s) and the "stand" start at a zero
command, 8 s: how many
last 8 s, how many of those are still (mean |hip speed| < 0.05 m/s over the last 2 s), the
speeds they move at instead and how the others end.
"""

import pathlib
import sys

import gymnasium as gym
import numpy as np
import torch

import biped_constraint_env  # noqa: F401
from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_actor, policy_batch_actor

torch.set_num_threads(1)
run, which = pathlib.Path(sys.argv[1]), sys.argv[2]
n = int(sys.argv[3]) if len(sys.argv) > 3 else 30
policy, norm, cfg, state = load_policy(run, which)
print(f"# {which}/ at {state['num_timesteps']} env steps")
batch = policy_batch_actor(policy, norm, cfg)
for row in cp.stop_rows(batch, cfg.env_kwargs(), list(range(700000, 700000 + n)), cfg.env_id)\
        if n else ():  # fmt: skip
    s = row["success"]
    drift = f", drift {row['drift_m_s_mean']:.2f} m/s" if "drift_m_s_mean" in row else ""
    print(f"{row['row']}: {s['successes']} of {s['episodes']}{drift}")
act = policy_actor(policy, norm, cfg)
for start in ("brake", "stand"):
    res = []
    for seed in range(700000, 700020):
        env = gym.make(cfg.env_id, **{**cfg.env_kwargs(), "start": start})
        obs, info = env.reset(seed=seed, options={"command": 0.0})
        speeds, end = [], None
        while info["t"] < 8.0:
            y0, t0 = info["hip_y"], info["t"]
            obs, _, term, trunc, info = env.step(act(obs))
            speeds.append((info["hip_y"] - y0) / max(info["t"] - t0, 1e-9))
            if term or trunc:
                end = info["termination_reason"] or "truncated"
                break
        res.append((end, float(np.abs(np.array(speeds[-100:])).mean())))
    lasted = sorted(v for e, v in res if e in (None, "truncated"))
    ends = [e for e, _ in res if e not in (None, "truncated")]
    print(f"from {start} at a zero command: {len(lasted)} of 20 last 8 s, "
          f"{sum(v < 0.05 for v in lasted)} still; speeds [m/s] {np.round(lasted, 2).tolist()}; "
          f"ends {ends}")  # fmt: skip
