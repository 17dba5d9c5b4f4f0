"""A joint PD hold of the brake start's posture under torque noise: how many of 20 stop.

The brake start (model 4 moving forward at 0-0.8 m/s) at a zero command, 4 s, Gaussian torque
noise drawn every 20 ms period; still: the hip's mean speed over the last 1 s below 0.05 m/s.
:func:`pd_hold` is shared with pd_brake_joints.py.

python pd_brake.py -> pd_brake.txt
"""

import gymnasium as gym
import numpy as np

import biped_constraint_env  # noqa: F401

STD = np.array([1.1, 2.6, 3.7, 3.4, 5.0])  # policies/ppo_command_50hz: exp(log_std) x 150 N m
SEEDS = range(700000, 700020)


def pd_hold(start: str, sigma) -> tuple[int, int, dict[str, int]]:
    """(held 4 s, still, {end reason: count}) of the PD hold from 20 ``start`` starts.

    Torques -100 (q - q0) - 10 qd + noise of std ``sigma`` [N m] (one value or one per joint),
    clipped to 150 N m, each 20 ms period, at a zero command.
    """
    held, still, ends = 0, 0, {}
    for seed in SEEDS:
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
            still += abs(ys[-1] - ys[-51]) / 1.0 < 0.05  # the hip's mean speed over the last 1 s
        else:
            ends[info["termination_reason"]] = ends.get(info["termination_reason"], 0) + 1
    return held, still, ends


if __name__ == "__main__":
    for label, sigma in [("0", 0.0), ("0.5", 0.5), ("1", 1.0),
                         ("half the command policy's", STD / 2),
                         ("the command policy's", STD)]:  # fmt: skip
        held, still, ends = pd_hold("brake", sigma)
        print(f"noise {label} N m: held 4 s {held} of 20, still {still}; ended: {ends}",
              flush=True)  # fmt: skip
