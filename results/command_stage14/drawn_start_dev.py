"""The slope rows from rest as the protocol ran them before each episode started at its command.

python drawn_start_dev.py RUN {best,final,checkpoint} [N] -> stdout: on slopes of -5 and +5
degrees from the policy's own start (the paper's rest posture), N development episodes each
(default 100; seeds 700000+), strict physics, the policy's env: each episode starts at the
command its reset draws (the env's own: 0-2 m/s, some zero) and is commanded 1.0 m/s from the
first control period, so that the policy's joystick ramp moves the held command from the
drawn one to 1.0 m/s; the walking success (at least 20 steps in 30 s) by the drawn command.
"""

import math
import sys

import gymnasium as gym
import numpy as np
import torch

import biped_constraint_env  # noqa: F401
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
seeds = list(range(700000, 700000 + (int(sys.argv[3]) if len(sys.argv) > 3 else 100)))
act = policy_batch_actor(policy, norm, cfg)
BINS = ((0.0, 0.2), (0.2, 0.5), (0.5, 1.0), (1.0, 1.5), (1.5, 2.01))
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; {len(seeds)} development episodes;"
      f" the env's command options: {cfg.env_kwargs().get('command')}")  # fmt: skip
print("| slope | all | " + " | ".join(f"drawn [{a}, {b})" for a, b in BINS) + " |")
print("|---|---|" + "---|" * len(BINS))
for deg in (-5.0, 5.0):
    kw = cfg.env_kwargs()
    kw["perturbations"] = {**(kw.get("perturbations") or {}), "slope_rad": math.radians(deg)}
    kw["termination"] = {**(kw.get("termination") or {}), "time_limit_s": 30.0}
    venv = gym.make_vec(cfg.env_id, num_envs=len(seeds), vectorization_mode="vector_entry_point",
                        **kw)  # fmt: skip
    obs, info = venv.reset(seed=seeds)
    drawn = info["command_m_s"].copy()
    live, steps = np.ones(len(seeds), bool), np.zeros(len(seeds), np.int64)
    while live.any():
        obs = obs.copy()
        obs[:, -1] = venv.unwrapped.set_command(np.full(len(seeds), 1.0))
        tau = np.asarray(act(obs), dtype=np.float64)
        tau[~live] = 0.0
        obs, _, term, trunc, info = venv.step(tau)
        steps = np.where(live, info["steps_completed"], steps)
        live &= ~(term | trunc)
    ok = steps >= 20
    cells = []
    for a, b in BINS:
        m = (drawn >= a) & (drawn < b)
        cells.append(f"{ok[m].sum()}/{m.sum()}")
    print(f"| {deg:+.1f} deg | {ok.sum()}/{len(seeds)} | " + " | ".join(cells) + " |")
    venv.close()
