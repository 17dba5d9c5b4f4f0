"""What each reward term pays per second as a run's network walks, on a development seed.

python terms_dev.py RUN {best,final,checkpoint} -> stdout: for commands 0.3 and 1.0 m/s held
from a mid-walk start (``start="stride"``, development seed 700000, the run's training env with
no perturbations, no resampling and no learning termination), each ``reward_<term>`` summed
over the periods from 3 s to 10 s, divided by that time: which terms ask the walk to change.
"""

import sys

import gymnasium as gym
import torch

import biped_constraint_env  # noqa: F401
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
act = policy_batch_actor(policy, norm, cfg)
kw = {**cfg.train_env_kwargs(), "start": "stride", "perturbations": None,
      "command": {"resample_s": None}}  # fmt: skip
kw.pop("termination", None)
env = gym.make(cfg.env_id, **kw)
dt = env.unwrapped.settings.dt
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; seed 700000; per second, 3-10 s")
for command in (0.3, 1.0):
    obs, info = env.reset(seed=700000, options={"command": command})
    total, n = {}, 0
    for k in range(round(10.0 / dt)):
        obs, _, term, trunc, info = env.step(act(obs[None])[0])
        if k >= round(3.0 / dt):
            for key, value in info.items():
                if key.startswith("reward_"):
                    total[key] = total.get(key, 0.0) + value
            n += 1
        if term or trunc:
            break
    per_s = ", ".join(f"{key[7:]} {v / (n * dt):.2f}" for key, v in total.items())
    print(f"command {command} m/s ({n * dt:.1f} s): {per_s}")
