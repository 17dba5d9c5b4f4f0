"""How much a run's network reads the gravity block: python gravity_weights.py RUN [which].

The change of the actor's first-layer preactivations between flat ground and a 5 degree
slope, through the run's own normaliser (the mean over the hidden units and the largest).
"""

import pathlib
import sys

import numpy as np

from training.ppo.policy_io import load_policy

run = pathlib.Path(sys.argv[1])
which = sys.argv[2] if len(sys.argv) > 2 else "best"
policy, norm, cfg, _ = load_policy(run, which)
w = policy.mlp_extractor.policy_net[0].weight.detach().numpy()
scale = np.sqrt(norm.var + 1e-8)
a = np.radians(5.0)
d_gravity = np.array([-np.sin(a), 1.0 - np.cos(a)])  # (-sin a, -cos a) minus flat (0, -1)
change = np.abs(w[:, 26:28] / scale[26:28] @ d_gravity)
print(
    f"{which}: gravity entries' statistics mean {norm.mean[26:28]}, std {scale[26:28]}; "
    f"a 5 deg slope moves the preactivations by {change.mean():.4f} on average, "
    f"{change.max():.4f} at most"
)
