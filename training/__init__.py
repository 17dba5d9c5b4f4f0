"""Experiments on ConstrainedBiped-v0: the open-loop baseline and PPO scripts."""
