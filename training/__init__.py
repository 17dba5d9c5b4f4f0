"""Experiments on ConstrainedBiped-v1: the open-loop baseline and PPO scripts."""
