"""Training and studies on ConstrainedBiped-v0: the Table 2 baseline, the controller, PPO."""

import training.plumbing.interrupts  # noqa: F401 (first: Ctrl-C while a command starts, one line)
