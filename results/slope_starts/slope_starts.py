"""Slopes at 1.0 m/s from the rest start and from mid-stride: where the uphill row fails.

    python results/slope_starts/slope_starts.py POLICY OUT.json

The command protocol's slope rows (``command_protocol.slope_rows``) start every episode at the
policy's own start (the paper's rest posture) placed on the slope. This runs the same rows
(1.0 m/s, 30 s, at least 20 steps as the protocol counts them, the 200 report episodes, strict
physics) from the rest start and from the env's mid-stride start (also at +-7.5 deg, beyond the
protocol), and gives for each the walking success, the ends, and when the failing episodes
ended.
"""

import json
import math
import sys
from pathlib import Path

import numpy as np
import torch

from training.plumbing.command_protocol import START_COMMAND_M_S, run_commanded
from training.plumbing.stats import MIN_STEPS, wilson_interval
from training.plumbing.outputs import write_file
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy_dir, out = Path(sys.argv[1]), Path(sys.argv[2])
policy, norm, cfg, _ = load_policy(policy_dir)
act = policy_batch_actor(policy, norm, cfg)
seeds = list(range(500000, 500200))
rows = []
for deg in (-7.5, -5.0, -2.5, 0.0, 2.5, 5.0, 7.5):
    for start in ("rest", "midstride"):
        kw = {**cfg.env_kwargs(), "start": start,
              "perturbations": {"slope_rad": math.radians(deg)}}  # fmt: skip
        eps = run_commanded(act, kw, seeds, lambda t, k: np.full(len(t), START_COMMAND_M_S),
                            30.0, cfg.env_id)  # fmt: skip
        ok = [e["steps_completed"] >= MIN_STEPS for e in eps]  # the protocol's walking success
        k = int(sum(ok))
        failed_t = [e["t"][-1] for e, o in zip(eps, ok, strict=True) if not o]
        ends: dict[str, int] = {}
        for e in eps:
            ends[e["end"]] = ends.get(e["end"], 0) + 1
        row = {"slope_deg": deg, "start": start, "successes": k, "episodes": len(eps),
               "ci95": wilson_interval(k, len(eps)), "ends": ends,
               "failed_end_t_s": [min(failed_t), float(np.median(failed_t)), max(failed_t)]
               if failed_t else None}  # fmt: skip
        rows.append(row)
        print(json.dumps(row), flush=True)
write_file(out, json.dumps({"policy": str(policy_dir), "seeds": [seeds[0], seeds[-1]],
                           "rows": rows}, indent=1) + "\n")  # fmt: skip
