"""Command protocol + slope rows of a run's snapshot on development episodes.

python protocol_dev.py RUN {best,final} N  -> markdown on stdout (seeds 700000..700000+N-1)
"""

import pathlib
import sys

import torch

from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
run, which, n = pathlib.Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
policy, norm, cfg, _ = load_policy(run, which)
act = policy_batch_actor(policy, norm, cfg)
seeds = list(range(700000, 700000 + n))
rows = cp.run_protocol(act, cfg.env_kwargs(), seeds, cfg.env_id)
rows += cp.slope_rows(act, cfg.env_kwargs(), seeds, cfg.env_id)
print(
    f"# protocol of {which}/ on {n} development episodes (seeds 700000-{700000 + n - 1}), "
    f"with the slope rows\n"
)
print(cp.markdown(rows))
