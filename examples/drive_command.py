"""Drive a command policy as a joystick would: from rest to 1.5 m/s, to a stop, and back to 1.0.

    python examples/drive_command.py POLICY [--which best|final] [--deadband D] [--ramp A]
                                     [--seed S]

POLICY: a command policy's directory (``policies/ppo_command_stop_50hz``, which stops and
stands at a zero command, ``policies/ppo_command_50hz``, which walks on, or a run directory that
``training.ppo.train`` wrote). One single env from the paper's rest posture, the network alone
in the loop; the command is set with ``env.unwrapped.set_command(v)`` before every control
period: 1.5 m/s for 8 s, then 0 for 8 s, then 1.0 m/s for 10 s. ``--deadband``/``--ramp`` set the
env's joystick options (``command={..., "deadband": D, "ramp_m_s2": A}``) over the policy's own.
Prints, each second, the command held and the hip's mean speed over that second, then whether
the stop came to rest by the evaluation protocol's test (``command_protocol.stands``: a control
period's mean hip speed below 0.05 m/s within 3 s of the stop, held 5 s) and how the episode
ended. Reads only POLICY; writes
nothing.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import biped_constraint_env  # noqa: F401  (registers ConstrainedBiped-v0)
from training.plumbing.command_protocol import period_speeds, stands
from training.ppo.policy_io import load_policy, policy_actor

SCHEDULE = ((8.0, 1.5), (16.0, 0.0), (26.0, 1.0))
"""(until [s], command [m/s]): the drive."""


def command_at(t: float) -> float:
    """The drive's command at time ``t`` [s]."""
    return next((v for until, v in SCHEDULE if t < until), SCHEDULE[-1][1])


def main(argv: list[str] | None = None) -> int:
    """Run the drive; exit status 0 when the stop came to rest and the episode ran to its end."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("policy")
    ap.add_argument("--which", default=None, help="snapshot (default: the policy's published one)")
    ap.add_argument("--deadband", type=float, default=None, help="joystick dead zone [m/s]")
    ap.add_argument("--ramp", type=float, default=None, help="joystick rate limit [m/s^2]")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    policy, norm, cfg, state = load_policy(args.policy, args.which)
    kw = cfg.env_kwargs()
    if kw.get("task") != "command":
        ap.error(f"{args.policy} is not a command policy (its env's task: {kw.get('task')!r})")
    joystick = {k: v for k, v in (("deadband", args.deadband), ("ramp_m_s2", args.ramp))
                if v is not None}  # fmt: skip
    kw["command"] = {**(kw.get("command") or {}), **joystick}
    env = gym.make("ConstrainedBiped-v0", **{**kw, "start": "rest"})
    act = policy_actor(policy, norm, cfg)
    obs, info = env.reset(seed=args.seed, options={"command": SCHEDULE[0][1]})
    print(f"{args.policy} ({state['num_timesteps']} env steps), command option {kw['command']}")
    ts, ys, held, end = [float(info["t"])], [float(info["hip_y"])], [], "the drive's end"
    while info["t"] < SCHEDULE[-1][0]:
        held.append(env.unwrapped.set_command(command_at(float(info["t"]))))
        obs, _, terminated, truncated, info = env.step(act(obs))
        ts.append(float(info["t"]))
        ys.append(float(info["hip_y"]))
        if terminated or truncated:
            end = info.get("termination_reason") or "time limit"
            break
    # the hip's mean speed over each whole second it ran, [k, k + 1] s
    seconds = np.arange(int(ts[-1] + 1e-9))
    y = np.interp(np.arange(len(seconds) + 1), ts, ys)
    speed = np.diff(y)
    print("  second  command held at its start [m/s]  hip speed [m/s]")
    for k in seconds:
        print(f"{k:4d}-{k + 1:<3d}  {held[int(np.searchsorted(ts, k))]:32.2f}  {speed[k]:15.3f}")
    # the protocol's stop test (training.plumbing.command_protocol.stands) from the moment
    # the drive sets 0: at rest within 3 s, held 5 s
    t, v = period_speeds({"t": ts, "hip_y": ys})
    stood, drift = stands(t, v, SCHEDULE[0][0], ts[-1])
    print(
        f"stop: {f'at rest, drift {drift:.3f} m/s' if stood else 'not at rest'}; steps "
        f"{int(info['steps_completed'])}; ended: {end} at {info['t']:.2f} s"
    )
    env.close()
    return 0 if stood and end == "the drive's end" else 1


if __name__ == "__main__":
    raise SystemExit(main())
