"""The hip's forward speed after a slow walk is told to stop, every 0.1 s until the episode ends.

python drift_trace.py RUN {best,final,checkpoint} WALK SEEDS -> stdout: per seed (a comma list;
development seeds, 700000+), ``t:MODEL:SPEED`` from 4.5 s (the period's start [s], the contact
model, the hip's mean forward speed over it [m/s]) under the protocol's stop commands (WALK
m/s from the rest start, 0 from 5 s), and how the episode ends (to 12 s).
"""

import sys

import gymnasium as gym
import numpy as np
import torch

import biped_constraint_env  # noqa: F401
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
walk, seeds = float(sys.argv[3]), [int(s) for s in sys.argv[4].split(",")]
act = policy_batch_actor(policy, norm, cfg)
venv = gym.make_vec(cfg.env_id, num_envs=len(seeds), vectorization_mode="vector_entry_point",
                    **cfg.env_kwargs())  # fmt: skip
obs, info = venv.reset(seed=seeds)
live, log, next_t = np.ones(len(seeds), bool), [[] for _ in seeds], np.full(len(seeds), 4.5)
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; walk {walk} m/s, 0 from 5 s")
while live.any() and info["t"].min() < 12.0:
    obs = obs.copy()
    obs[:, -1] = venv.unwrapped.set_command(np.where(info["t"] < 5.0, walk, 0.0))
    y0, t0 = info["hip_y"].copy(), info["t"].copy()
    obs, _, term, trunc, info = venv.step(np.asarray(act(obs), dtype=np.float64))
    for i in np.flatnonzero(live):
        if t0[i] >= next_t[i] - 1e-9:
            v = (info["hip_y"][i] - y0[i]) / max(info["t"][i] - t0[i], 1e-12)
            log[i].append(f"{t0[i]:.1f}:{info['mode'][i]}:{v:.2f}")
            next_t[i] += 0.1
        if term[i] or trunc[i]:
            live[i] = False
            log[i].append(f"end {info['termination_reason'][i] or 'time_limit'}")
for s, entries in zip(seeds, log, strict=True):
    print(s, " ".join(entries))
