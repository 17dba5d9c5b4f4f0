"""What a walk told to stop does, contact phase by contact phase, on development seeds.

python stop_trace.py RUN {best,final,checkpoint} [N] -> stdout: N episodes (seeds 700000+,
default 4) from the mid-stride start at a 1.0 m/s command; at 3 s the command becomes 0. One
line per episode: how it ends (None: it lasted to 9 s), then each contact phase after the
command changed as ``t:mMODEL@SPEED`` (its first control period's start [s], the model, the
hip's mean forward speed over that period [m/s]; 0.0 for a period cut at once by an event).
"""

import sys

import gymnasium as gym
import numpy as np
import torch

import biped_constraint_env  # noqa: F401
from training.ppo.policy_io import load_policy, policy_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
n = int(sys.argv[3]) if len(sys.argv) > 3 else 4
act = policy_actor(policy, norm, cfg)
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps")
for seed in range(700000, 700000 + n):
    env = gym.make(cfg.env_id, **cfg.env_kwargs())
    obs, info = env.reset(seed=seed, options={"command": 1.0})
    term = trunc = False
    while info["t"] < 3.0 and not (term or trunc):
        obs, _, term, trunc, info = env.step(act(obs))
    env.unwrapped.set_command(0.0)
    phases = []
    while info["t"] < 9.0 and not (term or trunc):
        y0, t0 = info["hip_y"], info["t"]
        model = int(np.argmax(obs[17:21])) + 1
        obs, _, term, trunc, info = env.step(act(obs))
        if not phases or phases[-1][1] != model:
            phases.append((t0, model, (info["hip_y"] - y0) / max(info["t"] - t0, 1e-9)))
    print(seed, "ends", info["termination_reason"] if term else None, "at", round(info["t"], 2),
          " ".join(f"{t:.2f}:m{m}@{v:.2f}" for t, m, v in phases[:30]))  # fmt: skip
