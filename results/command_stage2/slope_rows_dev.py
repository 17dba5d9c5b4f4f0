"""The uphill rows from rest on development episodes: python slope_rows_dev.py RUN {best,final} N.

Seeds 700000 to 700000 + N - 1; 1.0 m/s from the rest start on +2.5 and +5 degrees, the
protocol's walking success (at least 20 steps in 30 s); strict physics.
"""

import math
import pathlib
import sys

import torch

from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
run, which, n = pathlib.Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
policy, norm, cfg, _ = load_policy(run, which)
batch = policy_batch_actor(policy, norm, cfg)
conds = [(f"slope {d:+.1f} deg", {"slope_rad": math.radians(d)}) for d in (2.5, 5.0)]
seeds = list(range(700000, 700000 + n))
for r in cp.walk_rows(batch, cfg.env_kwargs(), seeds, cfg.env_id, conds):
    print(which, r["row"], r["success"]["successes"], "/", n, r["ends"])
