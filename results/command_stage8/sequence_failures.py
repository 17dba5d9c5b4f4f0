"""Where the command protocol's random sequences end in a fall: the command then and before.

python sequence_failures.py RUN {best,final,checkpoint} [N] -> stdout: per episode of the
protocol's sequence row (seeds 700000+, development; N, default 20), how it ends, when, the
command at the end and the one before it, and the time since the command last changed.
"""

import sys

import numpy as np
import torch

from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
n = int(sys.argv[3]) if len(sys.argv) > 3 else 20
act = policy_batch_actor(policy, norm, cfg)
seeds = list(range(700000, 700000 + n))
rng = np.random.default_rng(seeds[0] + 1)  # the draw of command_protocol.sequence_row
changes = [np.cumsum(rng.uniform(2.0, 5.0, 16)) for _ in seeds]
values = rng.uniform(0.0, 2.0, (n, 17))


def command(t, k):
    """The rows' commands at times ``t`` (as the protocol's sequence row)."""
    idx = [np.searchsorted(c, ti, side="right") for c, ti in zip(changes, t, strict=True)]
    return values[np.arange(len(t)), idx]


eps = cp.run_commanded(act, cfg.env_kwargs(), seeds, command, cp.SEQUENCE_S, cfg.env_id)
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps")
for k, ep in enumerate(eps):
    t_end = ep["t"][-1]
    i = int(np.searchsorted(changes[k], t_end, side="right"))
    since = t_end - (changes[k][i - 1] if i > 0 else 0.0)
    before = f"{values[k, i - 1]:.2f}" if i > 0 else "-"
    print(
        f"{ep['seed']} {ep['end']} at {t_end:.2f} s: command {values[k, i]:.2f} m/s "
        f"(before {before}), {since:.2f} s after it was set"
    )
