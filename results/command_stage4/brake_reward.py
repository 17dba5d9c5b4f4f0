"""The command reward of braking against walking on, from the brake start at a zero command.

python brake_reward.py [RUN [WEIGHT KERNEL]]: over 10 development starts (seeds 700000+), 4 s
each, the mean return and the mean reward per period of the joint PD hold of the start's
posture (torques -100 (q - q0) - 10 qd, no noise) and of a policy's published snapshot (RUN;
default the published command policy), with the env's command reward and with the `still`
term at that weight and kernel (default 1, 1). brake_reward.txt: no arguments.
"""

import pathlib
import sys

import gymnasium as gym
import numpy as np
import torch

import biped_constraint_env  # noqa: F401
from training.ppo.policy_io import load_policy, policy_actor

torch.set_num_threads(1)
args = sys.argv[1:]
run = pathlib.Path(args[0] if args else "policies/ppo_command_50hz")
weight, kernel = (float(args[1]), float(args[2])) if len(args) > 2 else (1.0, 1.0)
policy, norm, cfg, _ = load_policy(run, None)
act = policy_actor(policy, norm, cfg)
STILL = {"kind": "command", "weights": {"still": weight}, "kernels": {"still": kernel}}
for label, reward in [
    ("the env's command reward", None),
    (f"with still ({weight}, {kernel})", STILL),
]:
    kw = {**cfg.env_kwargs(), "start": "brake", **({"reward": reward} if reward else {})}
    for who in ("PD hold", f"{run.name}'s policy"):
        returns, per_period, ends = [], [], []
        for seed in range(700000, 700010):
            env = gym.make(cfg.env_id, **kw)
            obs, info = env.reset(seed=seed, options={"command": 0.0})
            u = env.unwrapped
            q0 = u.state.q.copy()
            rewards = []
            while info["t"] < 4.0:
                st = u.state
                pd = np.clip(-100 * (st.q[1:] - q0[1:]) - 10 * st.qd[1:], -150, 150)
                obs, r, te, tr, info = env.step(
                    pd.astype(np.float32) if who == "PD hold" else act(obs)
                )
                rewards.append(r)
                if te or tr:
                    ends.append(info["termination_reason"])
                    break
            returns.append(sum(rewards))
            per_period.append(sum(rewards) / len(rewards))
        print(f"{label}, {who}: return over 4 s {np.mean(returns):.1f}, per period "
              f"{np.mean(per_period):.3f}; {len(ends)} of 10 ended early {ends}")  # fmt: skip
