"""Training and studies on ConstrainedBiped-v0: the Table 2 baseline, the controller, PPO."""
