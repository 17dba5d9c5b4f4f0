"""Evaluate a trained policy (a run directory or the committed one) on seeded episodes.

    python -m training.evaluate POLICY_DIR [--episodes 10] [--seed 0] [--which final]
        [--compare] [--out DIR]

Runs N seeded episodes of the policy's env (its config; by default the walking task of
ConstrainedBiped-v0, default physics, strict checks) with the deterministic network and prints
completed steps (mean, std, min), distance, speed, torque cost and termination reasons. With
``--compare`` it runs, on the same seeds: the imitation result alone (the run's ``imitation``
snapshot, when the policy was warm-started from a teacher), the teacher (the model
controller) alone, the policy under 3x the reset noise and under a push, and the Table 2 open
loop. Writes ``evaluation.json``, ``figures/best.gif`` and Fig. 6-style strips of the best and
the worst episode into POLICY_DIR (or ``--out``).

The policy is loaded from weights (safetensors) and plain data (TOML, JSON, npz): nothing in
POLICY_DIR is unpickled (:mod:`training.policy_io`).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from training.policy_io import SNAPSHOTS, available, load_policy, policy_actor
from training.rollouts import PUSH_HIP_DV_M_S, PUSH_TIME_S, run_episodes, summarize, table_row

GIF_MAX_FRAMES = 500


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


def _rows_compare(run_dir: Path, actor, cfg, seeds) -> list[dict]:
    """The ``--compare`` rows: stresses of the policy, imitation alone, teacher, Table 2."""
    from training.model_controller import controller_from

    kw = cfg.env_kwargs()
    rows = [
        summarize(
            "policy, 3x reset noise",
            run_episodes(
                actor,
                {**kw, "reset_noise_scale": 3 * kw["reset_noise_scale"]},
                seeds,
                cfg.env_id,
                desc="3x noise",
            ),
        ),
        summarize(
            f"policy, push {PUSH_HIP_DV_M_S} m/s at {PUSH_TIME_S} s",
            run_episodes(actor, kw, seeds, cfg.env_id, push_at_s=PUSH_TIME_S, desc="push"),
        ),
    ]
    if available(run_dir, "imitation"):
        policy, norm, _, _ = load_policy(run_dir, "imitation")
        rows.append(
            summarize(
                "imitation alone (DART + DAgger, before PPO)",
                run_episodes(
                    policy_actor(policy, norm, cfg), kw, seeds, cfg.env_id, desc="imitation alone"
                ),
            )
        )
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
    print("Table 2 open loop (paper preset, then default physics at 2 ms)", flush=True)
    return rows + open_loop_baselines()


def main(argv: Sequence[str] | None = None) -> int:
    """Evaluate and write the outputs."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path, help="a run directory or a committed policy")
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0, help="episode i uses seed + i")
    ap.add_argument("--which", default="final", choices=sorted(SNAPSHOTS), help="snapshot")
    ap.add_argument("--compare", action="store_true", help="also run the baselines and stresses")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: RUN_DIR)")
    args = ap.parse_args(argv)
    if args.episodes < 1:
        ap.error("--episodes must be >= 1")
    if not (args.run_dir / "config.toml").is_file():
        ap.error(f"{args.run_dir} is not a run directory (no config.toml)")
    t0 = time.time()
    print(f"loading {args.run_dir} ({args.which}) and the simulator", flush=True)
    import torch

    torch.set_num_threads(1)
    try:
        policy, norm, cfg, state = load_policy(args.run_dir, args.which)
    except FileNotFoundError as e:
        ap.error(str(e))
    import biped_constraint_env  # noqa: F401  (compiles on a machine's first run)

    print(
        f"loaded in {time.time() - t0:.0f} s ({state.get('num_timesteps', 0)} PPO env steps); "
        f"{args.episodes} episodes of up to 30 s each",
        flush=True,
    )
    out_dir = args.out or args.run_dir
    (out_dir / "figures").mkdir(parents=True, exist_ok=True)
    seeds = list(range(args.seed, args.seed + args.episodes))
    actor = policy_actor(policy, norm, cfg)
    label = "policy" + ("" if cfg.base_controller == "" else " (residual on the model controller)")
    main_row = summarize(
        label, run_episodes(actor, cfg.env_kwargs(), seeds, cfg.env_id, desc="policy episodes")
    )
    print(table_row(main_row), flush=True)
    rows = [main_row]
    if args.compare:
        rows += _rows_compare(args.run_dir, actor, cfg, seeds)
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
