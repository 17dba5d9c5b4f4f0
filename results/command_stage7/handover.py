"""A walker and a stander handing over at a stop: each alone and the two gated, development seeds.

python handover.py WALKER WHICH STANDER WHICH V [N] [FORCES] -> stdout.

1. The stander alone at a zero command, 8 s, 20 episodes (seeds 700000+) from each of the
   starts "stand", "brake", "stride_stand" and "stride_brake": how many last 8 s, how many of
   those are still (mean |hip speed| < 0.05 m/s over the last 2 s).
2. The two as one map from the observation to the torques: the stander's where the command is
   exactly 0, the contact state is model 4 (both feet down) and the hip's forward speed (the
   observation's ``hip_vy``) is below V [m/s]; the walker's elsewhere. The command protocol's
   stop and restart rows (``command_protocol.stop_rows``: a walk at 0.3-2.0 m/s, told 0, at rest
   within 3 s and held 5 s, then 1.0 m/s) on N development episodes (default 20).
3. With FORCES (not a network): the same stop test, single envs, with one change to the
   stander's observation's three contact-force entries (after a period: the forces under that
   period's torques, at the handover the walker's): "start": in its first period after the
   walker, the forces at that state under zero torque, as at every start it trained from (the
   simulator is asked); "mean": in that first period, the stander's observation mean (its
   normalised input 0); "mean_always": the mean in every period it acts.

A check of what a gate read from the observation could hand over, not a trained network.
"""

import sys

import gymnasium as gym
import numpy as np
import torch

import biped_constraint_env  # noqa: F401
from biped_constraint_env.observation import OBS_NAMES
from biped_constraint_env.simulator import evaluate
from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_actor, policy_batch_actor

torch.set_num_threads(1)
MODE_4, HIP_VY, COMMAND = OBS_NAMES.index("mode_4"), OBS_NAMES.index("hip_vy"), -1
FORCES = slice(OBS_NAMES.index("f_stance_toe"), OBS_NAMES.index("f_contact_normal") + 1)


def stander_rows(obs, v):
    """(n,) bool: the rows of ``obs`` (n, d) the stander acts on (the docstring's gate)."""
    return (obs[:, COMMAND] == 0.0) & (obs[:, MODE_4] == 1.0) & (obs[:, HIP_VY] < v)


def stop_with_forces(walk, stand, cfg, v, seeds, how, mean):
    """Check 3: (successes, a line per episode); ``how``: FORCES; ``mean``: the stander's."""
    commands = np.random.default_rng(int(seeds[0])).uniform(0.3, 2.0, len(seeds))  # stop_rows'
    wins, rows = 0, []
    for seed, c in zip(seeds, commands, strict=True):
        env = gym.make(cfg.env_id, **cfg.env_kwargs())
        u = env.unwrapped
        obs, info = env.reset(seed=seed, options={"command": float(c)})
        gated, t, speeds, modes, done = False, [], [], [], False
        while info["t"] < cp.STOP_AT_S + cp.STOP_WITHIN_S + cp.HOLD_S and not done:
            if info["t"] >= cp.STOP_AT_S and info["command_m_s"] != 0.0:
                u.set_command(0.0)
                obs = obs.copy()
                obs[COMMAND] = 0.0
            if stander_rows(obs[None], v)[0]:
                if not gated or how == "mean_always":
                    obs = obs.copy()
                    obs[FORCES] = (evaluate(u.params, u.state, np.zeros(5), u.options)[1][:3]
                                   if how == "start" else mean)  # fmt: skip
                gated, a = True, stand(obs[None])[0]
            else:
                gated, a = False, walk(obs[None])[0]
            y0, t0 = info["hip_y"], info["t"]
            obs, _, term, trunc, info = env.step(a)
            done = term or trunc
            t.append(info["t"])
            modes.append(info["mode"])
            speeds.append((info["hip_y"] - y0) / max(info["t"] - t0, 1e-9))
        ok, drift = cp.stands(np.array(t), np.array(speeds), cp.STOP_AT_S, info["t"])
        wins += ok and not done
        held = [k for k, m in enumerate(modes) if all(x == 4 for x in modes[k:])]
        since = f"{t[held[0]]:.2f} s" if held else "never"
        late = np.abs(speeds[-100:]).mean()
        end = info["termination_reason"] if done else None
        rows.append(f"{seed} ({c:.2f} m/s): ends {end}, in model 4 to the end from {since},"
                    f" last 2 s |v| {late:.3f}, drift {drift:.3f}")  # fmt: skip
    return wins, rows


def zero_command_check(act, cfg, start, n=20):
    """(episodes that last 8 s, of those still, their speeds) from ``start`` at a zero command."""
    speeds = []
    for seed in range(700000, 700000 + n):
        env = gym.make(cfg.env_id, **{**cfg.env_kwargs(), "start": start})
        obs, info = env.reset(seed=seed, options={"command": 0.0})
        v = []
        while info["t"] < 8.0:
            y0, t0 = info["hip_y"], info["t"]
            obs, _, term, trunc, info = env.step(act(obs))
            v.append((info["hip_y"] - y0) / max(info["t"] - t0, 1e-9))
            if term or trunc:
                break
        if not (term or trunc):
            speeds.append(float(np.abs(v[-100:]).mean()))
    return len(speeds), sum(s < 0.05 for s in speeds), sorted(np.round(speeds, 2).tolist())


def main():
    """The two checks of the docstring."""
    walker, wwhich, stander, swhich, v = sys.argv[1:6]
    n, v = int(sys.argv[6]) if len(sys.argv) > 6 else 20, float(v)
    forces = sys.argv[7] if len(sys.argv) > 7 else ""
    pw, nw, cw, sw = load_policy(walker, wwhich)
    ps, ns, cs, ss = load_policy(stander, swhich)
    print(
        f"# walker {walker} {wwhich}/ ({sw['num_timesteps']} env steps), stander {stander}"
        f" {swhich}/ ({ss['num_timesteps']}); gate: command 0, model 4, hip_vy < {v} m/s"
    )
    walk, stand = policy_batch_actor(pw, nw, cw), policy_batch_actor(ps, ns, cs)
    if forces:
        if forces not in ("start", "mean", "mean_always"):
            raise SystemExit(f"FORCES is start, mean or mean_always, not {forces!r}")
        mean = np.asarray(ns.mean)[FORCES]
        seeds = list(range(700000, 700000 + n))
        wins, rows = stop_with_forces(walk, stand, cw, v, seeds, forces, mean)
        print(f"gated, the stander's force entries {forces}: stop {wins} of {n}")
        print("\n".join(rows))
        return
    one = policy_actor(ps, ns, cs)
    for start in ("stand", "brake", "stride_stand", "stride_brake"):
        lasted, still, speeds = zero_command_check(one, cw, start)
        print(f"stander from {start}: {lasted} of 20 last 8 s, {still} still; speeds {speeds}")

    def act(obs):
        obs = np.asarray(obs)
        gate = stander_rows(obs, v)
        return np.where(gate[:, None], stand(obs), walk(obs))

    for row in cp.stop_rows(act, cw.env_kwargs(), list(range(700000, 700000 + n)), cw.env_id):
        drift = f", drift {row['drift_m_s_mean']:.2f} m/s" if "drift_m_s_mean" in row else ""
        print(f"gated {row['row']}: {row['success']['successes']} of {row['success']['episodes']}"
              f"{drift}")  # fmt: skip


if __name__ == "__main__":
    main()
