"""Can double support hold and brake a walk told to stop? Two checks at the walk's own states.

python double_support.py RUN WHICH N [COMMAND] [KV] [ENTRY] -> stdout. N development episodes (seeds
700000+) from the mid-stride start at COMMAND (default 1.0 m/s) for 3 s, then a zero command.
KV = 0: the first check only; KV < 0: the third check only.

1. ``entries``: at every control period that starts in model 4 (double support) over the next
   4 s, the old stance toe's normal force f_n [N] under the policy's torques, under zero
   torques, and the largest any torque within +-150 N m gives with both ends of the new stance
   foot loaded (a linear program: at one state the forces are affine in the torques).
2. ``brake``: the same walk, but from its first model-4 period on, each period's torques
   (held over the period, as the env does) from a linear program at the period's start: the
   hip's acceleration closest to -KV times its velocity (default 3 /s), then closest to a joint
   PD hold of the entry posture (100 N m/rad, 10 N m s/rad), with f_n >= 20 N and both ends of
   the stance foot >= 5 N; where that is infeasible, the torques that load all three most
   evenly. ENTRY (default 1): the law takes over at the walk's ENTRY-th period that starts in
   model 4 (the policy's own torques before it). Printed: how the episode ends, the hip's mean
   speed per period [m/s].
3. ``static`` (KV < 0): at every period that starts in model 4 over the next 3 s, whether that
   posture can be held at rest: the smallest sum of |joint accelerations| [rad/s^2] any torque
   within the limits gives at the posture with the rates set to zero, with f_n >= 20 N and both
   ends of the stance foot >= 5 N (a linear program; 0: a static hold exists).

A model-based law, not a policy: it asks what the physics allows at the walk's own states.
"""

import dataclasses
import sys

import gymnasium as gym
import numpy as np
import torch
from scipy.optimize import linprog

import biped_constraint_env  # noqa: F401
from biped_constraint_env.hybrid import FC_CONTACT, FC_HEEL, FC_TOE
from biped_constraint_env.simulator import evaluate, keypoints
from training.ppo.policy_io import load_policy, policy_actor

LIM, FN_MIN, FOOT_MIN = 150.0, 20.0, 5.0
torch.set_num_threads(1)


def forces_and_rates(env, st):
    """At ``st``: (qdd0, forces0) under zero torques and their derivatives in the torques."""
    u = env.unwrapped
    ev = lambda tau: evaluate(u.params, st, np.asarray(tau, float), u.options)  # noqa: E731
    qdd0, f0, _ = ev(np.zeros(5))
    cols = [ev(np.eye(5)[i]) for i in range(5)]
    dq = np.stack([c[0] - qdd0 for c in cols], 1)
    return qdd0, f0, dq, np.stack([c[1] - f0 for c in cols], 1)


def best_toe_force(f0, F):
    """The largest f_n any torque within the limits gives with the stance foot loaded [N]."""
    res = linprog(-F[FC_CONTACT], A_ub=-F[[FC_TOE, FC_HEEL]], b_ub=f0[[FC_TOE, FC_HEEL]],
                  bounds=[(-LIM, LIM)] * 5)  # fmt: skip
    return f0[FC_CONTACT] - res.fun if res.success else float("nan")


def hip_jacobian(params, st, h=1e-6):
    """d(hip position)/dq at ``st`` (2, 6), by central differences of the keypoints."""
    J = np.zeros((2, 6))
    for i in range(6):
        for s in (1, -1):
            q = st.q.copy()
            q[i] += s * h
            J[:, i] += s * keypoints(params, dataclasses.replace(st, q=q))["hip"] / (2 * h)
    return J


def brake_torque(env, st, q0, kv):
    """The linear program of the docstring's check 2: (torques, whether it was feasible)."""
    u = env.unwrapped
    qdd0, f0, Q, F = forces_and_rates(env, st)
    H = hip_jacobian(u.params, st)
    v = H @ st.qd
    eps = 1e-5  # the hip's acceleration at zero torque: d/dt (H qd) along the motion
    st2 = dataclasses.replace(st, q=st.q + eps * st.qd, qd=st.qd + eps * qdd0)
    a0 = (hip_jacobian(u.params, st2) @ st2.qd - v) / eps
    A_h, a_des = H @ Q, -kv * v
    pd = np.clip(-100.0 * (st.q[1:] - q0) - 10.0 * st.qd[1:], -LIM, LIM)
    # variables: torques (5), |hip acceleration error| (2), |torque - PD| (5)
    A, b = [], []

    def row(tau=None, err=None, dev=None):
        z = np.zeros
        return np.r_[z(5) if tau is None else tau, z(2) if err is None else err,
                     z(5) if dev is None else dev]  # fmt: skip

    for k, lo in ((FC_CONTACT, FN_MIN), (FC_TOE, FOOT_MIN), (FC_HEEL, FOOT_MIN)):
        A.append(row(tau=-F[k]))
        b.append(f0[k] - lo)
    for k in range(2):
        e = np.eye(2)[k]
        A += [row(tau=A_h[k], err=-e), row(tau=-A_h[k], err=-e)]
        b += [a_des[k] - a0[k], a0[k] - a_des[k]]
    for i in range(5):
        e = np.eye(5)[i]
        A += [row(tau=e, dev=-e), row(tau=-e, dev=-e)]
        b += [pd[i], -pd[i]]
    cost = np.r_[np.zeros(5), 1.0, 1.0, 0.01 * np.ones(5)]
    res = linprog(cost, A_ub=np.array(A), b_ub=np.array(b),
                  bounds=[(-LIM, LIM)] * 5 + [(0, None)] * 7)  # fmt: skip
    if res.success:
        return res.x[:5], True
    G = F[[FC_CONTACT, FC_TOE, FC_HEEL]]
    res = linprog(np.r_[np.zeros(5), -1.0], A_ub=np.c_[-G, np.ones(3)],
                  b_ub=f0[[FC_CONTACT, FC_TOE, FC_HEEL]],
                  bounds=[(-LIM, LIM)] * 5 + [(None, None)])  # fmt: skip
    return (res.x[:5] if res.success else pd), False


def static_residual(env, st):
    """Check 3 at ``st``: the smallest sum |qdd| of a hold at rest, or NaN (no loaded hold)."""
    qdd0, f0, Q, F = forces_and_rates(env, dataclasses.replace(st, qd=np.zeros_like(st.qd)))
    n = Q.shape[0]
    A = [np.r_[-F[k], np.zeros(n)] for k in (FC_CONTACT, FC_TOE, FC_HEEL)]
    b = [f0[FC_CONTACT] - FN_MIN, f0[FC_TOE] - FOOT_MIN, f0[FC_HEEL] - FOOT_MIN]
    for i in range(n):  # -e_i <= qdd0_i + Q_i tau <= e_i
        A += [np.r_[Q[i], -np.eye(n)[i]], np.r_[-Q[i], -np.eye(n)[i]]]
        b += [-qdd0[i], qdd0[i]]
    res = linprog(np.r_[np.zeros(5), np.ones(n)], A_ub=np.array(A), b_ub=np.array(b),
                  bounds=[(-LIM, LIM)] * 5 + [(0, None)] * n)  # fmt: skip
    return res.fun if res.success else float("nan")


def walk_to_zero(cfg, act, seed, command):
    """A fresh env, the policy walking 3 s at ``command`` from mid-stride, then told 0."""
    env = gym.make(cfg.env_id, **cfg.env_kwargs())
    obs, info = env.reset(seed=seed, options={"command": command})
    term = trunc = False
    while info["t"] < 3.0 and not (term or trunc):
        obs, _, term, trunc, info = env.step(act(obs))
    env.unwrapped.set_command(0.0)
    return env, obs, info, term or trunc


def main():
    """The two checks of the docstring, per episode."""
    run, which, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    command = float(sys.argv[4]) if len(sys.argv) > 4 else 1.0
    kv = float(sys.argv[5]) if len(sys.argv) > 5 else 3.0
    entry = int(sys.argv[6]) if len(sys.argv) > 6 else 1
    policy, norm, cfg, state = load_policy(run, which)
    act = policy_actor(policy, norm, cfg)
    print(f"# {run} {which}/ at {state['num_timesteps']} env steps; command {command} m/s, then 0")
    for seed in range(700000, 700000 + n):
        env, obs, info, done = walk_to_zero(cfg, act, seed, command)
        if kv < 0.0:
            res = []
            while info["t"] < 6.0 and not done:
                if int(env.unwrapped.state.mode) == 4:
                    res.append(static_residual(env, env.unwrapped.state))
                obs, _, term, trunc, info = env.step(act(obs))
                done = term or trunc
            print(
                seed,
                f"static: {len(res)} model-4 periods; a hold at rest exists at"
                f" {sum(r < 1e-6 for r in res)}; largest residual {max(res, default=0):.3g}",
            )
            continue
        entries = []
        while info["t"] < 7.0 and not done:
            st, a = env.unwrapped.state, act(obs)
            if int(st.mode) == 4:
                _, f0, _, F = forces_and_rates(env, st)
                fa = f0 + F @ a
                entries.append(f"{info['t']:.2f}: {fa[FC_CONTACT]:+.0f} / {f0[FC_CONTACT]:+.0f}"
                               f" / {best_toe_force(f0, F):+.0f}")  # fmt: skip
            obs, _, term, trunc, info = env.step(a)
            done = term or trunc
        print(seed, "entries (t: f_n policy / zero torque / best [N]):", "; ".join(entries[:6]))
        if kv == 0.0:
            continue
        env, obs, info, done = walk_to_zero(cfg, act, seed, command)
        q0, speeds, lp, seen, was4 = None, [], 0, 0, False
        while info["t"] < 11.0 and not done:
            st = env.unwrapped.state
            seen += q0 is None and int(st.mode) == 4 and not was4
            was4 = int(st.mode) == 4
            if q0 is None and seen == entry:
                q0, t_in = st.q[1:].copy(), info["t"]
            if q0 is None:
                a = act(obs)
            else:
                a, ok = brake_torque(env, st, q0, kv)
                lp += ok
            y0, t0 = info["hip_y"], info["t"]
            obs, _, term, trunc, info = env.step(a)
            done = term or trunc
            if q0 is not None:
                speeds.append((info["hip_y"] - y0) / max(info["t"] - t0, 1e-9))
        print(seed, f"brake from {t_in:.2f} s: ends {info['termination_reason'] if term else None}"
              f" at {info['t']:.2f} s in model {info['mode']}; {lp} of {len(speeds)} periods"
              f" feasible; hip speed", " ".join(f"{v:.2f}" for v in speeds))  # fmt: skip


if __name__ == "__main__":
    main()
