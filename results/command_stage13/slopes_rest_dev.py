"""The slopes from the rest start at 1.0 m/s of a run's network on development seeds.

python slopes_rest_dev.py RUN {best,final,checkpoint} [N] -> stdout: the walking success on
slopes of -5, -2.5, +2.5 and +5 degrees from the policy's own start (the paper's rest posture),
commanded 1.0 m/s, strict physics, N development episodes each (default 100; seeds 700000+):
the rows of ``command_protocol.slope_rows`` that start from rest, and only those.
"""

import math
import sys

import torch

from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
seeds = list(range(700000, 700000 + (int(sys.argv[3]) if len(sys.argv) > 3 else 100)))
act = policy_batch_actor(policy, norm, cfg)
slopes = [(f"slope {deg:+.1f} deg", {"slope_rad": math.radians(deg)}) for deg in (-5, -2.5, 2.5, 5)]
rows = cp.walk_rows(act, cfg.env_kwargs(), seeds, cfg.env_id, slopes)
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; {len(seeds)} development episodes")
print(cp.markdown(rows), end="")
