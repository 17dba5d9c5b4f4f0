"""Which joint's noise ends the PD hold: the published policy's noise with some joints at 0.5 N m.

The joint PD hold of pd_brake.py (-100 (q - q0) - 10 qd, clipped to 150 N m, each 20 ms period)
from 20 brake starts and 20 standing starts at a zero command, 4 s, with Gaussian torque noise
of the published command policy's std per joint (front ankle, front knee, hip, rear knee, rear
ankle: 1.1, 2.6, 3.7, 3.4, 5.0 N m), some joints lowered to 0.5 N m; still: the hip's mean
speed over the last 1 s below 0.05 m/s.

python pd_brake_joints.py -> pd_brake_joints.txt
"""

import gymnasium as gym
import numpy as np

import biped_constraint_env  # noqa: F401

STD = np.array([1.1, 2.6, 3.7, 3.4, 5.0])  # policies/ppo_command_50hz: exp(log_std) x 150 N m
VARIANTS = {
    "every joint the policy's": STD,
    "rear ankle 0.5": np.r_[STD[:4], 0.5],
    "rear knee and ankle 0.5": np.r_[STD[:3], 0.5, 0.5],
    "front ankle 0.5": np.r_[0.5, STD[1:]],
    "both ankles 0.5": np.r_[0.5, STD[1:4], 0.5],
    "hip and rear ankle 0.5": np.r_[STD[:2], 0.5, STD[3], 0.5],
}
for start in ("brake", "stand"):
    for label, sigma in VARIANTS.items():
        held, still, ends = 0, 0, {}
        for seed in range(700000, 700020):
            env = gym.make("ConstrainedBiped-v0", task="command", start=start,
                           termination={"time_limit_s": 4})  # fmt: skip
            obs, info = env.reset(seed=seed, options={"command": 0.0})
            u = env.unwrapped
            q0 = u.state.q.copy()
            rng = np.random.default_rng(seed)
            ys = []
            while True:
                st = u.state
                ys.append(info["hip_y"])
                noise = sigma * rng.standard_normal(5)
                tau = np.clip(-100 * (st.q[1:] - q0[1:]) - 10 * st.qd[1:] + noise, -150, 150)
                obs, r, te, tr, info = env.step(tau.astype(np.float32))
                if te or tr:
                    break
            if info["t"] >= 4.0 - 1e-9:
                held += 1
                still += abs(ys[-1] - ys[-51]) < 0.05
            else:
                ends[info["termination_reason"]] = ends.get(info["termination_reason"], 0) + 1
        print(f"{start}, {label}: held 4 s {held} of 20, still {still}; ended: {ends}", flush=True)
