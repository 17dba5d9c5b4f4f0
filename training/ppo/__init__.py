"""The PPO recipe: training, its configuration, the SB3 adapter, imitation, policy files, sweeps."""
