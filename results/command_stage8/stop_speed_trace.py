"""The hip's forward speed, control period by control period, of a walk told to stop.

python stop_speed_trace.py RUN {best,final,checkpoint} SEEDS -> stdout: per seed (a comma list;
use development seeds, 700000+), how the episode ends (None: it lasted to 9 s), then every
other control period after the command changed as ``tMODEL:SPEED`` (the period's start [s],
the contact model, the hip's mean forward speed over it [m/s]). The episode starts mid-stride
at a 1.0 m/s command; at 3 s the command becomes 0 (as ``../command_stage5/stop_trace.py``).
"""

import sys

import gymnasium as gym
import numpy as np
import torch

import biped_constraint_env  # noqa: F401
from biped_constraint_env.observation import OBS_MODE
from training.ppo.policy_io import load_policy, policy_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
act = policy_actor(policy, norm, cfg)
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps")
for seed in [int(s) for s in sys.argv[3].split(",")]:
    env = gym.make(cfg.env_id, **cfg.env_kwargs())
    obs, info = env.reset(seed=seed, options={"command": 1.0})
    term = trunc = False
    while info["t"] < 3.0 and not (term or trunc):
        obs, _, term, trunc, info = env.step(act(obs))
    env.unwrapped.set_command(0.0)
    row = []
    while info["t"] < 9.0 and not (term or trunc):
        y0, t0 = info["hip_y"], info["t"]
        model = int(np.argmax(obs[OBS_MODE])) + 1
        obs, _, term, trunc, info = env.step(act(obs))
        row.append(f"{t0:.2f}m{model}:{(info['hip_y'] - y0) / max(info['t'] - t0, 1e-9):+.2f}")
    print(seed, "ends", info["termination_reason"] if term else None, "at", round(info["t"], 2))
    print("  ".join(row[::2]))
