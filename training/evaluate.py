"""Evaluate a trained policy (a run directory or the committed one) on seeded episodes.

    python -m training.evaluate POLICY_DIR [--episodes 10] [--seed 0] [--compare] [--out DIR]

Runs N seeded episodes of the policy's env (its config; by default the walking task of
ConstrainedBiped-v0, default physics, strict checks) with the deterministic network and prints
completed steps (mean, std, min), distance, speed, torque cost and termination reasons. With
``--compare`` it runs, on the same seeds: the imitation result alone (the run's ``imitation/``
checkpoint, when the policy was warm-started from a teacher), the teacher (the model
controller) alone, the policy under 3x the reset noise and under a push, and the Table 2 open
loop. Writes ``evaluation.json``, ``figures/best.gif`` and Fig. 6-style strips of the best and
the worst episode into POLICY_DIR (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

GIF_MAX_FRAMES = 500
PUSH_HIP_DV_M_S = (-0.3, 0.0)
"""The push of ``--compare``: a sudden change of the hip's velocity (y, z) [m/s] (backward),
applied once, 2 s into the episode, through the constraint-consistent joint rates."""
PUSH_TIME_S = 2.0


def load(run: Path, which: str = "final"):
    """(model, vecnorm, config) of a run directory.

    ``which``: "final", "best", "checkpoints" or "imitation" (the warm start before PPO).
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from training.common import parse_config
    from training.sb3_vec import make_sb3_vec_env
    from training.train_ppo import PPOConfig

    cfg = parse_config(PPOConfig, ["--config", str(run / "config.toml")], "")
    where = run if which == "final" else run / which
    model = PPO.load(where / "model.zip", device="cpu")
    dummy = make_sb3_vec_env(1, 0, cfg.env_kwargs(), "dummy", cfg.env_id)
    vecnorm = VecNormalize.load(str(where / "vecnormalize.pkl"), dummy)
    vecnorm.training = False
    vecnorm.norm_reward = False
    return model, vecnorm, cfg


def policy_actor(model, vecnorm, cfg) -> Callable[[np.ndarray], np.ndarray]:
    """Obs (24,) -> torques (5,) [N m] of the deterministic policy (through its ActionMap)."""
    amap = cfg.action_map()

    def act(obs: np.ndarray) -> np.ndarray:
        o = vecnorm.normalize_obs(obs[None, :].astype(np.float32)) if vecnorm else obs[None, :]
        action, _ = model.predict(o, deterministic=True)
        return amap(action, obs[None, :])[0]

    return act


def push(env, dv=PUSH_HIP_DV_M_S) -> None:
    """Change the hip's velocity by ``dv`` (y, z) [m/s] at once, keeping the model's contacts.

    The joint rates change by the least-norm solution of J_hip dqd = dv among the rates that
    keep the current model's contacts (theta0 frozen in models 1 and 4, the point contact of
    models 3 and 4 at rest); the state is set in the simulator directly.
    """
    from biped_constraint_env.kinematics import nb_point_jacobian
    from biped_constraint_env.model import SC_HEEL5, SC_TOE5

    u = env.unwrapped
    st = u.state
    ch = u.params.chain(st.stance_side)
    J_hip = nb_point_jacobian(ch.packed, st.q, 3, 0.0)
    rows = [J_hip[0], J_hip[1]]
    rhs = [dv[0], dv[1]]
    mode = int(st.mode)
    if mode in (1, 4):
        e = np.zeros(6)
        e[0] = 1.0
        rows.append(e)
        rhs.append(0.0)
    if mode in (3, 4):  # the swing foot's heel (3) or toe (4) stays on the ground
        s = float(ch.packed_scalars[SC_HEEL5 if mode == 3 else SC_TOE5])
        J = nb_point_jacobian(ch.packed, st.q, 5, s)
        rows += [J[0], J[1]]
        rhs += [0.0, 0.0]
    A = np.array(rows)
    dq = np.linalg.lstsq(A, np.array(rhs), rcond=None)[0]
    u._sim.qd[0] = st.qd + dq


def run_episodes(
    actor: Callable[[np.ndarray], np.ndarray],
    env_kwargs: dict,
    seeds: Sequence[int],
    env_id: str = "ConstrainedBiped-v0",
    record=None,
    push_at_s: float | None = None,
    desc: str = "",
) -> list[dict]:
    """Run one episode per seed; per episode: steps, distance, speed, torque cost, end.

    ``record(env, episode_index)`` is called before every step if given (frames for figures).
    ``push_at_s``: apply :func:`push` once at that time [s]. Torque cost: the integral of
    sum(tau^2) dt over the episode per metre of hip travel [N^2 m s].
    """
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401
    from training.common import progress

    env = gym.make(env_id, **env_kwargs, render_mode="rgb_array" if record else None)
    out = []
    for k, seed in enumerate(progress(seeds, len(seeds), desc, enabled=bool(desc))):
        obs, info = env.reset(seed=int(seed))
        y0, t_prev, cost, ret, done, pushed = info["hip_y"], 0.0, 0.0, 0.0, False, False
        while not done:
            if record:
                record(env, k)
            if push_at_s is not None and not pushed and info["t"] >= push_at_s:
                push(env)
                pushed = True
            tau = actor(obs)
            obs, r, term, trunc, info = env.step(tau)
            cost += float(np.sum(np.square(tau))) * (info["t"] - t_prev)
            t_prev = info["t"]
            ret += r
            done = term or trunc
        dist = info["hip_y"] - y0
        out.append(
            {
                "seed": int(seed),
                "steps_completed": int(info["steps_completed"]),
                "distance_m": dist,
                "speed_m_s": dist / max(info["t"], 1e-9),
                "torque_cost": cost / max(dist, 1e-3) if dist > 0 else float("nan"),
                "return": ret,
                "t_s": info["t"],
                "end": info["termination_reason"] or "time_limit",
            }
        )
    env.close()
    return out


def summarize(label: str, eps: list[dict]) -> dict:
    """Mean/std/min of steps, distance and speed, mean torque cost, and the ends."""
    s = np.array([e["steps_completed"] for e in eps], dtype=float)
    d = np.array([e["distance_m"] for e in eps])
    v = np.array([e["speed_m_s"] for e in eps])
    c = np.array([e["torque_cost"] for e in eps])
    return {
        "controller": label,
        "episodes": eps,
        "steps_mean": s.mean(),
        "steps_std": s.std(),
        "steps_min": int(s.min()),
        "distance_mean_m": d.mean(),
        "distance_std_m": d.std(),
        "speed_mean_m_s": v.mean(),
        "torque_cost_mean": float(np.nanmean(c)) if np.isfinite(c).any() else float("nan"),
        "ends": dict(Counter(e["end"] for e in eps)),
    }


def table_row(r: dict) -> str:
    """One markdown row of a :func:`summarize` result."""
    return (
        f"| {r['controller']} | {r['steps_mean']:.1f} ± {r['steps_std']:.1f}, min {r['steps_min']}"
        f" | {r['distance_mean_m']:.2f} ± {r['distance_std_m']:.2f} | {r['speed_mean_m_s']:.2f} "
        f"| {r['torque_cost_mean']:.0f} | {r['ends']} |"
    )


def open_loop_baselines() -> list[dict]:
    """The Table 2 open loop (paper preset, and the accurate default), run now."""
    from training.open_loop import OpenLoopConfig, run

    rows = []
    for label, kw in (
        ("Table 2 open loop, task='paper'", {}),
        (
            "Table 2 open loop, default preset, 2 ms",
            {"preset": "default", "dt": 0.002, "max_periods": 5000},
        ),
    ):
        out = run(OpenLoopConfig(gif=False, progress=False, **kw), record_frames=False)
        eps = [
            {
                "seed": 0,
                "steps_completed": out["steps_completed"],
                "distance_m": out["distance_m"],
                "speed_m_s": float("nan"),
                "torque_cost": float("nan"),
                "return": float("nan"),
                "t_s": out["t_end_s"],
                "end": out["end_reason"],
            }
        ]
        rows.append(summarize(label, eps))
    return rows


def figures(actor, cfg, seed_best: int, seed_worst: int, eps_by_seed: dict, out_dir: Path):
    """GIF (real time, 50 fps, at most GIF_MAX_FRAMES frames) and strips of two episodes."""
    from training import plots

    for name, seed in (("best", seed_best), ("worst", seed_worst)):
        frames, images = [], []

        def record(env, _k, frames=frames, images=images, name=name):
            u = env.unwrapped
            # one frame per 20 ms of simulated time (real-time GIF at 50 fps, whatever dt)
            if frames and u.state.t < frames[-1]["t"] + 0.02 - 1e-9:
                return
            frames.append({"t": u.state.t, "keypoints": u.keypoints()})
            if name == "best" and len(images) < GIF_MAX_FRAMES:
                images.append(env.render())

        run_episodes(actor, cfg.env_kwargs(), [seed], cfg.env_id, record=record)
        if images:
            plots.save_gif(images, out_dir / "figures" / f"{name}.gif", fps=50)
        e = eps_by_seed[seed]
        plots.stick_strip(
            frames[: 15 * 50],  # the first 15 s
            out_dir / "figures" / f"{name}_strip.png",
            f"{name} episode (seed {seed}): {e['steps_completed']} steps, "
            f"{e['distance_m']:.2f} m (first 15 s)",
            every=max(min(len(frames), 750) // 30, 1),
        )


def main(argv: Sequence[str] | None = None) -> int:
    """Evaluate and write the outputs."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0, help="episode i uses seed + i")
    ap.add_argument(
        "--which", default="final", choices=["final", "best", "checkpoints", "imitation"]
    )
    ap.add_argument("--compare", action="store_true", help="also run the baselines and stresses")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: RUN_DIR)")
    args = ap.parse_args(argv)
    if args.episodes < 1:
        ap.error("--episodes must be >= 1")
    if not (args.run_dir / "config.toml").is_file():
        ap.error(f"{args.run_dir} is not a run directory (no config.toml)")
    print(
        "loading (the first run on a machine compiles the simulator: about a minute, once)",
        flush=True,
    )
    t0 = time.time()
    import torch

    torch.set_num_threads(1)
    model, vecnorm, cfg = load(args.run_dir, args.which)
    out_dir = args.out or args.run_dir
    (out_dir / "figures").mkdir(parents=True, exist_ok=True)
    seeds = list(range(args.seed, args.seed + args.episodes))
    actor = policy_actor(model, vecnorm, cfg)
    label = "policy" + ("" if cfg.base_controller == "" else " (residual on the model controller)")
    main_row = summarize(
        label, run_episodes(actor, cfg.env_kwargs(), seeds, cfg.env_id, desc="policy episodes")
    )
    rows = [main_row]
    if args.compare:
        kw = cfg.env_kwargs()
        rows.append(
            summarize(
                "policy, 3x reset noise",
                run_episodes(
                    actor,
                    {**kw, "reset_noise_scale": 3 * kw["reset_noise_scale"]},
                    seeds,
                    cfg.env_id,
                    desc="3x noise",
                ),
            )
        )
        rows.append(
            summarize(
                f"policy, push {PUSH_HIP_DV_M_S} m/s at {PUSH_TIME_S} s",
                run_episodes(actor, kw, seeds, cfg.env_id, push_at_s=PUSH_TIME_S, desc="push"),
            )
        )
        if (args.run_dir / "imitation" / "model.zip").is_file():
            im = policy_actor(*load(args.run_dir, "imitation"))
            rows.append(
                summarize(
                    "imitation alone (DART + DAgger, before PPO)",
                    run_episodes(im, kw, seeds, cfg.env_id, desc="imitation alone"),
                )
            )
        from training.model_controller import controller_from

        spec = cfg.teacher or "model"
        teacher = controller_from(spec)
        rows.append(
            summarize(
                f"model controller ({spec!r}, the teacher) alone",
                run_episodes(teacher, kw, seeds, cfg.env_id, desc="model controller"),
            )
        )
        rows.append(
            summarize(
                f"model controller, push {PUSH_HIP_DV_M_S} m/s",
                run_episodes(
                    teacher, kw, seeds, cfg.env_id, push_at_s=PUSH_TIME_S, desc="controller, push"
                ),
            )
        )
        rows += open_loop_baselines()
    steps = np.array([e["steps_completed"] for e in main_row["episodes"]], dtype=float)
    dist = np.array([e["distance_m"] for e in main_row["episodes"]])
    order = np.argsort(steps + 1e-3 * dist)
    by_seed = {e["seed"]: e for e in main_row["episodes"]}
    print("writing the GIF and the strips", flush=True)
    figures(actor, cfg, seeds[order[-1]], seeds[order[0]], by_seed, out_dir)
    summary = {"which": args.which, "seeds": seeds, "results": rows}
    (out_dir / "evaluation.json").write_text(json.dumps(summary, indent=1, default=float) + "\n")
    print(
        f"\n{args.episodes} seeded episodes (seeds {seeds[0]}-{seeds[-1]}), "
        f"{cfg.env_id} {cfg.env_kwargs().get('task', '')} task, strict physics:"
    )
    print(
        "| controller | complete steps (mean ± std, min) | distance [m] | speed [m/s] | "
        "torque cost [N² m s per m] | ends |"
    )
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(table_row(r))
    print(
        f"\nfigures: {out_dir / 'figures'} (best.gif, best_strip.png, worst_strip.png); "
        f"summary: {out_dir / 'evaluation.json'}; {time.time() - t0:.0f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
