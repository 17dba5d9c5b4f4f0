"""How a run's network walks at constant commands, on development seeds.

python speeds_dev.py RUN {best,final,checkpoint} [N] -> stdout: per command of
``command_protocol.TRACK_COMMANDS_M_S``, the mean hip speed after 3 s (signed: above the command
is too fast), its spread over episodes, the mean step time and the step length (speed times
step time), over N development episodes of 15 s (default 10; seeds 700000+), in the run's env.
The tracking row's error says how far; this says which way and by which of cadence and step
length.
"""

import sys

import numpy as np
import torch

from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
kw = cfg.env_kwargs()
seeds = list(range(700000, 700000 + (int(sys.argv[3]) if len(sys.argv) > 3 else 10)))
act = policy_batch_actor(policy, norm, cfg)
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; {len(seeds)} development episodes")
print(
    "| command [m/s] | mean speed after 3 s [m/s] | spread | step time [s] | step length [m] "
    "| ran 15 s |"
)
print("|---|---|---|---|---|---|")
for c in cp.TRACK_COMMANDS_M_S:
    eps = cp.run_commanded(act, kw, seeds, lambda t, k, c=c: np.full(len(t), c), 15.0, cfg.env_id)
    speeds, steps = [], []
    for ep in eps:
        t, y, marks = np.asarray(ep["t"]), np.asarray(ep["hip_y"]), np.asarray(ep["step_t_s"])
        if t[-1] > cp.SETTLE_S:
            speeds.append((y[-1] - np.interp(cp.SETTLE_S, t, y)) / (t[-1] - cp.SETTLE_S))
        steps += list(np.diff(marks)[marks[1:] > cp.SETTLE_S])
    v, dt = np.mean(speeds), np.mean(steps) if steps else np.nan
    ran = sum(ep["end"] == "time_limit" for ep in eps)
    print(f"| {c} | {v:.3f} | {np.std(speeds):.3f} | {dt:.3f} | {v * dt:.3f} | {ran}/{len(eps)} |")
