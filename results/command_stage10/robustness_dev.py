"""The command protocol's robustness rows of a run's network on development seeds.

python robustness_dev.py RUN {best,final,checkpoint} [N] -> stdout: the push table (hip Δv
0.2-1.6 m/s forward and backward, commanded 1.0 m/s; ``command_protocol.push_rows``), the
slopes of -5° to +5° from the rest start and from mid-stride (``slope_rows``) and the model
rows (``model_rows``), on N development episodes each (default 20; seeds 700000+, as
``evaluate --robustness --episodes N --seed 700000``), in the run's env. The joystick options
play no part: every row runs at a constant 1.0 m/s.
"""

import sys

import torch

from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
kw = cfg.env_kwargs()
seeds = list(range(700000, 700000 + (int(sys.argv[3]) if len(sys.argv) > 3 else 20)))
act = policy_batch_actor(policy, norm, cfg)
rows = [*cp.push_rows(act, kw, seeds, cfg.env_id), *cp.slope_rows(act, kw, seeds, cfg.env_id),
        *cp.model_rows(act, kw, seeds, cfg.env_id)]  # fmt: skip
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; {len(seeds)} development episodes")
print(cp.markdown(rows), end="")
