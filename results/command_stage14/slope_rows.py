"""The command protocol's slope rows of a run's network: from rest and from mid-stride.

python slope_rows.py RUN {best,final,checkpoint} [N [SEED]] -> stdout: ``command_protocol.
slope_rows`` (slopes of -5 to +5 degrees at 1.0 m/s, from the policy's own start and from
mid-stride: the walking success) on N episodes (default 200) of seeds SEED+ (default 500000,
the report seeds, as ``evaluate --robustness``), strict physics, the run's env as it is.
"""

import sys

import torch

from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
first = int(sys.argv[4]) if len(sys.argv) > 4 else 500000
seeds = list(range(first, first + (int(sys.argv[3]) if len(sys.argv) > 3 else 200)))
rows = cp.slope_rows(policy_batch_actor(policy, norm, cfg), cfg.env_kwargs(), seeds, cfg.env_id)
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; seeds {first}+; "
      f"command option {cfg.env_kwargs().get('command')}")  # fmt: skip
print(cp.markdown(rows), end="")
