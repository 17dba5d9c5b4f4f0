"""The slopes from the rest start at 1.0 m/s, reached by the joystick's ramp from a zero command.

python slopes_ramp_dev.py RUN {best,final,checkpoint} [N] -> stdout: the walking success on
slopes of -5, -2.5, 0, +2.5 and +5 degrees from the policy's own start (the paper's rest
posture), N development episodes each (default 100; seeds 700000+), strict physics, the
policy's env: each episode starts at a zero command and is commanded 1.0 m/s from the second
control period on, so that the policy's joystick options (its ramp, its dead zone) bring the
held command up from 0 as a joystick pushed forward from rest would. The protocol's slope rows
start at 1.0 m/s instead (``command_protocol.slope_rows``).
"""

import math
import sys
from collections import Counter

import numpy as np
import torch

from training.plumbing import command_protocol as cp
from training.plumbing.stats import success
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
seeds = list(range(700000, 700000 + (int(sys.argv[3]) if len(sys.argv) > 3 else 100)))
act = policy_batch_actor(policy, norm, cfg)
rows = []
for deg in (-5.0, -2.5, 0.0, 2.5, 5.0):
    kw = cfg.env_kwargs()
    kw["perturbations"] = {**(kw.get("perturbations") or {}), "slope_rad": math.radians(deg)}
    eps = cp.run_commanded(act, kw, seeds,
                           lambda t, k: np.full(len(t), 0.0 if k == 0 else cp.START_COMMAND_M_S),
                           30.0, cfg.env_id)  # fmt: skip
    rows.append({"row": f"slope {deg:+.1f} deg, from a zero command ramped to 1.0 m/s",
                 "success": success([e["steps_completed"] for e in eps]),
                 "ends": dict(Counter(e["end"] for e in eps))})  # fmt: skip
print(
    f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; {len(seeds)} development episodes;"
    f" the env's command options: {kw.get('command')}"
)
print(cp.markdown(rows), end="")
