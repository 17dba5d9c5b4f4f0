"""Sim-to-sim: a policy trained under the constraint model, run in the soft-contact MuJoCo twin.

Every episode starts from the state the constraint env's reset gives for its seed (the same
start, mapped into MuJoCo: :meth:`biped_constraint_env.twin.Twin.set_state`); every 20 ms the
policy reads the observation the constraint env would compute from the twin's state in the
paper's terms (the estimated model and stance leg, the joint angles and rates in that
numbering, the hip, the normal forces; the contact clock and the command as the env's own
parts give them), and its torques are held for the period. The twin has no strict contact
checks: an episode ends at 30 s or at a fall (:meth:`~biped_constraint_env.twin.Twin.fallen`).
A success is the walking success: at least 20 completed steps (the twin's touchdowns).

``python -m training.evaluation.sim_to_sim POLICY --start rest --episodes 200``: the success
with its 95% interval in the twin, beside the constraint model's on the same seeds (its own
batched env, strict checks).
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np

from training.plumbing.stats import success


def twin_episode(act, env_kwargs: dict, seed: int, episode_s: float = 30.0,
                 options=None, command: float | None = None) -> dict:  # fmt: skip
    """One episode of ``act`` in the twin, from the constraint env's start for ``seed``.

    ``act``: obs (1, d) -> torques (1, 5) [N m].
    """
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401
    from biped_constraint_env.clock import ContactClock
    from biped_constraint_env.observation import (
        OBS_HIGH,
        OBS_LOW,
        OBSERVATION_BLOCKS,
        nb_observe_row,
    )
    from biped_constraint_env.twin import Twin, TwinOptions

    env = gym.make("ConstrainedBiped-v0", **env_kwargs)
    reset_options = None if command is None else {"command": command}
    env.reset(seed=seed, options=reset_options)
    core = env.unwrapped.core
    s = core.settings
    st = env.unwrapped.state
    params = env.unwrapped.params
    twin = Twin(params, options or TwinOptions())
    twin.set_state(st.q, st.qd, st.stance_side, st.root_y, st.mode)
    dt = s.dt
    clock = ContactClock(1, dt) if core.clock is not None else None
    if clock is not None:
        clock.start(np.array([0]), np.array([st.mode]), st.qd[None, :])
    chs, scs = params.packed
    blocks = s.observation.blocks
    fall_z = s.fall_hip_height_m
    obs = np.empty(24)
    hip = np.empty(4)
    K = np.empty((6, 11))
    y0 = None
    end, t = "time_limit", 0.0
    n_periods = round(episode_s / dt)
    for _ in range(n_periods):
        q, qd, root = twin.paper_state()
        ist = np.array([twin.mode, twin.side, twin.steps, 0], np.int64)
        fst = np.array([twin.time, root, 0.0, 0.0, 0.0, 0.0])
        nb_observe_row(chs, scs, q, qd, ist, fst, twin.paper_forces(), obs,
                       hip, OBS_LOW, OBS_HIGH, K)  # fmt: skip
        y0 = hip[0] if y0 is None else y0
        if twin.fallen(fall_z):
            end = "fall"
            break
        extra = []
        for b in blocks:
            if b == "phase":
                extra.append(clock.features()[0])
            elif b == "command":
                extra.append(np.array([core.commands.features()[0, 0]]))
            else:
                extra.append(OBSERVATION_BLOCKS[b].features(core)[0])
        full = np.concatenate([obs, *extra])[None, :]
        tau = np.asarray(act(full), float)[0]
        twin.step(tau, dt)
        if clock is not None:
            clock.advance(np.array([twin.mode]), np.array([twin.steps]))
        t = twin.time
    env.close()
    return {"seed": int(seed), "steps_completed": int(twin.steps), "end": end,
            "t_s": round(t, 3), "distance_m": float(hip[0] - y0)}  # fmt: skip


def constraint_episodes(act, env_kwargs: dict, seeds, command: float | None = None) -> list:
    """The same seeds' 30 s episodes in the constraint model (the batched env, strict checks).

    With ``command``, held from the reset
    (:func:`~training.plumbing.command_protocol.run_commanded`).
    """
    if command is None:
        from training.plumbing.rollouts import run_episodes_batched

        return run_episodes_batched(act, env_kwargs, seeds, episode_s=30.0)
    from training.plumbing.command_protocol import run_commanded

    return run_commanded(act, env_kwargs, seeds, lambda t, k: np.full(len(t), command), 30.0)


def main(argv: list[str] | None = None) -> int:
    """Run a policy in the twin on report seeds; print and write the success."""
    from training.plumbing.common import command
    from training.ppo.config import REPORT_SEED_OFFSET
    from training.ppo.policy_io import (
        ObsNormalizer,
        open_policy,
        policy_batch_actor,
        published_snapshot,
    )

    ap = argparse.ArgumentParser(prog="sim_to_sim", description=__doc__.split("\n\n")[0])
    ap.add_argument("policy", type=Path)
    ap.add_argument("--start", default=None, help="the env's start (default: the policy's)")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=REPORT_SEED_OFFSET, help="the first seed")
    ap.add_argument("--command", type=float, default=None, help="a held command [m/s]")

    @command("sim_to_sim")
    def run(a) -> int:
        which, _ = published_snapshot(a.policy)
        policy, norm, cfg, _, _ = open_policy(a.policy, which)
        act = policy_batch_actor(policy, ObsNormalizer(norm), cfg)
        kw = cfg.env_kwargs()
        if a.start is not None:
            kw = {**kw, "start": a.start}
        t0 = time.time()
        seeds = range(a.seed, a.seed + a.episodes)
        eps = [twin_episode(act, kw, s, command=a.command) for s in seeds]
        ref = constraint_episodes(act, kw, seeds, a.command)
        out = {
            "policy": str(a.policy),
            "start": kw.get("start"),
            "command": a.command,
            "seeds": [a.seed, a.seed + a.episodes - 1],
            "wall_s": round(time.time() - t0, 1),
        }
        for name, rows in (("twin", eps), ("constraint", ref)):
            out[name] = {"success": success([e["steps_completed"] for e in rows]),
                         "steps_mean": float(np.mean([e["steps_completed"] for e in rows])),
                         "ends": dict(Counter(e["end"] for e in rows))}  # fmt: skip
        print(json.dumps(out, indent=1))  # writes nothing: the rows go to standard output
        return 0

    return run(ap.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
