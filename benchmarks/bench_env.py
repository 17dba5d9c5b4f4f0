"""Environment speed, side by side with Gymnasium's Walker2d-v5 (MuJoCo), in one run.

    python -m benchmarks.bench_env [--pd-only]

Both envs are driven the same way: ``gym.make`` (default wrappers), a fixed sequence of
seeded random actions scaled to 5% of the action bound, reset on termination/truncation
(reset time included). Prints us per env.step, and env-steps/s of the batched vector env
against Walker2d-v5's ``make_vec(..., vectorization_mode="sync")``, with the ratios (the
batched env on ``--env-threads`` numba threads, all cores by default: the env alone in the
process; and once on one thread, the env's default). Every
timing runs ``--rounds`` times, interleaved with the others; each figure is its best round
(the machine's slow spells only ever add time).

Random torques end a walking-task episode in its first period (the stance toe pulls off the
ground), so those rows time a reset and one terminated period per episode. The "walking" rows
replay the actions the model controller (``model:teacher_robust``) gave,
recorded before the timing from the same seeds: the env walks the same way again (the simulator
is deterministic) and no reset is timed. They time ``env.step`` as it is used.

Last, the cost per simulated second of PD targets with the PD law at the physics rate
(targets held over a 20 ms period, the law every 5 ms or 1 ms) against torque actions on the
same trajectories (the held PD law's torques, replayed as torque actions: the same motion),
from rest at the rest pose until the swing foot lands (``--pd-only``: these rows alone).
"""

from __future__ import annotations

import os
import time

import gymnasium as gym
import numpy as np

import biped_constraint_env  # noqa: F401  (registers ConstrainedBiped-v0)
from training.plumbing.common import CliParser, command

ACTION_FRACTION = 0.05  # random actions at 5% of the bound: episodes last tens of steps


def walking_actions(n: int, seed: int = 0) -> np.ndarray:
    """The model controller's actions over n periods of the default walking task from seed."""
    from training.controller.model_controller import controller_from

    env = gym.make("ConstrainedBiped-v0", max_episode_steps=n + 1)
    ctl = controller_from("model:teacher_robust")
    obs, _ = env.reset(seed=seed)
    acts = np.empty((n, 5), np.float32)
    for k in range(n):
        acts[k] = ctl(obs)
        obs, _, te, tr, info = env.step(acts[k])
        if te or tr:
            raise RuntimeError(f"the controller stopped walking at period {k}: {info}")
    return acts


def walking_actions_batched(n: int, num_envs: int, seed: int = 0) -> np.ndarray:
    """The model controller's actions (n, num_envs, 5) over n periods of the batched default
    walking task reset with ``seed`` (sub-environment i seeded seed + i)."""
    from training.controller.model_controller import controller_from

    venv = gym.make_vec(
        "ConstrainedBiped-v0",
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        max_episode_steps=n + 1,
    )
    ctl = controller_from("model:teacher_robust")
    obs, _ = venv.reset(seed=seed)
    acts = np.empty((n, num_envs, 5), np.float32)
    for k in range(n):
        acts[k] = ctl(obs)
        obs, _, te, tr, _ = venv.step(acts[k])
        if np.any(te | tr):
            raise RuntimeError(
                f"the controller stopped walking at period {k} in {np.flatnonzero(te | tr)}"
            )
    venv.close()
    return acts


def per_step_us(env_id: str, n: int, seed: int = 0, acts=None, **kwargs) -> float:
    """us per env.step: seeded random actions (5% of the bound, warmed up, resets timed), or
    a replay of ``acts`` from the reset with ``seed`` (no warm-up, so no reset is timed)."""
    replay = acts is not None
    env = gym.make(env_id, **({"max_episode_steps": len(acts) + 1} if replay else {}), **kwargs)
    env.reset(seed=seed)
    if not replay:
        rng = np.random.default_rng(seed)
        high = env.action_space.high
        acts = (rng.uniform(-1, 1, (n, high.size)) * high * ACTION_FRACTION).astype(np.float32)
        for k in range(min(n, 200)):
            _, _, te, tr, _ = env.step(acts[k])
            if te or tr:
                env.reset()
    t0 = time.perf_counter()
    for a in acts:
        _, _, te, tr, _ = env.step(a)
        if te or tr:
            env.reset()
    dt = time.perf_counter() - t0
    env.close()
    return dt / len(acts) * 1e6


def vec_steps_per_s(
    env_id: str, num_envs: int, mode: str, n: int, seed: int = 0, acts=None, **kwargs
) -> float:
    """env-steps/s of a vector env: seeded random actions (as :func:`per_step_us`, warmed up),
    or a replay of ``acts`` (n, num_envs, 5) from the reset with ``seed``."""
    replay = acts is not None
    if replay:
        kwargs["max_episode_steps"] = len(acts) + 1
    venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode, **kwargs)
    venv.reset(seed=seed)
    if not replay:
        rng = np.random.default_rng(seed)
        high = venv.single_action_space.high
        acts = (rng.uniform(-1, 1, (n, num_envs, high.size)) * high * ACTION_FRACTION).astype(
            np.float32
        )
        for k in range(min(n, 50)):
            venv.step(acts[k])
    n = len(acts)
    t0 = time.perf_counter()
    for k in range(n):
        venv.step(acts[k])
    dt = time.perf_counter() - t0
    venv.close()
    return n * num_envs / dt


PD_EPISODES = 200
"""Episodes of the PD-cost timing (each a held rest pose until the swing foot lands, ~0.5 s)."""


def pd_episodes(dt: float, pd_dt: float, seeds) -> list[np.ndarray]:
    """Each seed's episode of PD targets at the rest pose (zero action), from rest, as the
    torques the PD law applied in each period (``info["torque"]``)."""
    env = gym.make("ConstrainedBiped-v0", action={"kind": "pd", "dt": pd_dt}, dt=dt, start="rest")
    out = []
    for seed in seeds:
        env.reset(seed=seed)
        taus, done = [], False
        while not done:
            _, _, te, tr, info = env.step(np.zeros(5))
            taus.append(info["torque"])
            done = te or tr
        out.append(np.array(taus))
    return out


def us_per_sim_second(seeds, dt: float, actions=None, **kwargs) -> float:
    """Wall time [us] per simulated second over the seeds' episodes from rest: PD targets at
    the rest pose (``actions`` None) or a replay of recorded torques, one list per seed."""
    env = gym.make("ConstrainedBiped-v0", dt=dt, start="rest", **kwargs)
    wall = sim = 0.0
    for k, seed in enumerate(seeds):
        env.reset(seed=seed)
        acts = actions[k] if actions is not None else np.zeros((10**6, 5))
        t0 = time.perf_counter()
        for a in acts:
            _, _, te, tr, info = env.step(a)
            if te or tr:
                break
        wall += time.perf_counter() - t0
        sim += info["t"]
    return wall / sim * 1e6


def pd_cost(rounds: int) -> None:
    """Print the cost per simulated second of PD targets with the law at the physics rate
    against torque actions (the same trajectories: the held law's torques replayed)."""
    seeds = range(PD_EPISODES)
    held20 = pd_episodes(0.02, 0.02, seeds)
    held5 = pd_episodes(0.005, 0.005, seeds)
    rows = {
        "torques, 20 ms periods (the held PD law's, replayed)": lambda: us_per_sim_second(
            seeds, 0.02, held20
        ),
        "torques, 5 ms periods (the walking task's; replayed)": lambda: us_per_sim_second(
            seeds, 0.005, held5
        ),
        "PD targets held 20 ms, the PD law every 5 ms": lambda: us_per_sim_second(
            seeds, 0.02, action={"kind": "pd", "dt": 0.005}
        ),
        "PD targets held 20 ms, the PD law every 1 ms": lambda: us_per_sim_second(
            seeds, 0.02, action={"kind": "pd", "dt": 0.001}
        ),
    }
    best = {label: np.inf for label in rows}
    for _ in range(rounds):
        for label, fn in rows.items():
            best[label] = min(best[label], fn())
    t20, t5, pd5, pd1 = best.values()
    print(f"\nPD at the physics rate against torques, us per simulated second (best of {rounds}):")
    for label, v in best.items():
        print(f"  {label}: {v:,.0f}")
    for name, v, ref in (("20 ms torques", pd5, t20), ("5 ms torques", pd5, t5)):
        r = v / ref
        print(
            f"  PD every 5 ms / {name}: {r:.2f} (target <= 1.5: {'met' if r <= 1.5 else 'MISSED'})"
        )
    print(f"  PD every 1 ms / 20 ms torques: {pd1 / t20:.2f} (finer servo, no target)")


@command("bench_env")
def main(argv=None) -> int:
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=5000, help="env.step calls per timing")
    ap.add_argument("--num-envs", type=int, default=256, help="sub-environments of the vector envs")
    ap.add_argument(
        "--rounds", type=int, default=5, help="interleaved rounds; each figure is the best"
    )
    ap.add_argument(
        "--env-threads",
        type=int,
        default=os.cpu_count(),
        help="numba threads of the batched env (num_threads; the env's default is 1)",
    )
    ap.add_argument("--pd-only", action="store_true", help="only the PD-cost rows (no MuJoCo)")
    args = ap.parse_args(argv)
    if args.pd_only:
        pd_cost(args.rounds)
        return 0
    for module in ("mujoco", "imageio"):  # Walker2d-v5, checked before any timing
        try:
            __import__(module)
        except ImportError:
            ap.error(f"{module} is missing: the benchmark needs pip install -e '.[bench]'")
    env_id = "ConstrainedBiped-v0"
    threads = {"num_threads": args.env_threads}
    n_vec = max(args.steps // args.num_envs, 20)
    acts = walking_actions(args.steps)
    acts_b = walking_actions_batched(n_vec * 4, args.num_envs)
    rows = {  # label -> (single env: us per env.step, batched: env-steps/s)
        "Walker2d-v5": (
            lambda: per_step_us("Walker2d-v5", args.steps),
            lambda: vec_steps_per_s("Walker2d-v5", args.num_envs, "sync", n_vec),
        ),
        f"default, walking (a controller's recorded actions, no resets), batched on "
        f"{args.env_threads} threads": (
            lambda: per_step_us(env_id, args.steps, acts=acts),
            lambda: vec_steps_per_s(
                env_id, args.num_envs, "vector_entry_point", 0, acts=acts_b, **threads
            ),
        ),
        "default, walking, batched on 1 thread (the env's default num_threads)": (
            lambda: per_step_us(env_id, args.steps, acts=acts),
            lambda: vec_steps_per_s(env_id, args.num_envs, "vector_entry_point", 0, acts=acts_b),
        ),
    }
    for label, kw in (
        ("default, random actions (a reset and one period per episode)", {}),
        (
            "task='paper', preset='default': 20 ms, error-controlled RK4_LIMEX",
            {"task": "paper", "preset": "default"},
        ),
        (
            "task='paper', preset='fixed_step': 20 ms, RK4_LIMEX x 8",
            {"task": "paper", "preset": "fixed_step"},
        ),
        ("task='paper', preset='fast': 20 ms, RK2 x 4", {"task": "paper", "preset": "fast"}),
    ):
        rows[label] = (
            lambda kw=kw: per_step_us(env_id, args.steps, **kw),
            lambda kw=kw: vec_steps_per_s(
                env_id, args.num_envs, "vector_entry_point", n_vec * 4, **kw, **threads
            ),
        )
    best = {label: [np.inf, 0.0] for label in rows}
    for r in range(args.rounds):  # interleaved, so that a slow spell of the machine hits all
        for label, (single, batched) in rows.items():
            best[label][0] = min(best[label][0], single())
            best[label][1] = max(best[label][1], batched())
        print(f"round {r + 1}/{args.rounds} done", flush=True)
    walker, walker_s = best.pop("Walker2d-v5")
    print(
        f"best of {args.rounds} rounds. Walker2d-v5: env.step {walker:.1f} us | make_vec sync, "
        f"{args.num_envs} envs: {walker_s:.0f} steps/s"
    )
    for label, (ours, ours_b) in best.items():
        r1, r2 = ours / walker, ours_b / walker_s
        print(
            f"{env_id} {label}: env.step {ours:.1f} us (ratio {r1:.3f}, target <= 0.1: "
            f"{'met' if r1 <= 0.1 else 'MISSED'}) | batched {ours_b:.0f} steps/s (ratio "
            f"{r2:.1f}, target >= 50: {'met' if r2 >= 50 else 'MISSED'})"
        )
    pd_cost(args.rounds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
