"""Evaluate a trained PPO run directory (or the committed policy) on seeded episodes.

    python -m training.evaluate RUN_DIR [--episodes 10] [--seed 0] [--which final|best]

Runs N seeded episodes of the run's env (v1 or v2) with its reset noise and the deterministic
policy; prints mean, std and min of completed walking steps and distance, the termination
reasons, and a table that puts the policy next to the open-loop baselines; writes
``evaluation.json``, ``figures/best.gif``, ``figures/worst.gif`` and Fig. 6-style strips of the
best and the worst episode into RUN_DIR (or ``--out``). With a base controller it also runs
the base alone (zero residual) on the same seeds, for comparison. The committed policy is the
run directory ``policies/ppo_model_residual``.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

GIF_MAX_FRAMES = 500


def load(run: Path, which: str):
    """(model, vecnorm, config) of a run directory; ``which``: "final", "best", "checkpoints"."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

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
    del DummyVecEnv
    return model, vecnorm, cfg


def baselines() -> list[dict]:
    """The open-loop baselines, run now with the committed settings (deterministic)."""
    from training.open_loop import OpenLoopConfig, run

    rows = []
    for label, kw in (
        ("Table 2, paper preset", {}),
        ("Table 2, default preset", {"preset": "default", "dt": 0.002, "max_periods": 5000}),
    ):
        out = run(OpenLoopConfig(gif=False, progress=False, **kw), record_frames=False)
        rows.append(
            {
                "controller": label,
                "steps_completed": out["steps_completed"],
                "distance_m": out["distance_m"],
                "end": out["end_reason"],
            }
        )
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """Evaluate and write the outputs."""
    import torch

    from training import plots
    from training.train_ppo import evaluate_policy_episodes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0, help="episode i uses seed + i")
    ap.add_argument("--which", default="final", choices=["final", "best", "checkpoints"])
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: RUN_DIR)")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    model, vecnorm, cfg = load(args.run_dir, args.which)
    out_dir = args.out or args.run_dir
    (out_dir / "figures").mkdir(parents=True, exist_ok=True)
    eps = evaluate_policy_episodes(model, vecnorm, cfg, args.episodes, args.seed)
    steps = np.array([e["steps_completed"] for e in eps], dtype=float)
    dist = np.array([e["distance_m"] for e in eps])
    best, worst = int(np.argmax(steps + 1e-3 * dist)), int(np.argmin(steps + 1e-3 * dist))
    for name, idx in (("best", best), ("worst", worst)):
        frames, images = [], []

        def record(env, ep, frames=frames, images=images):
            u = env.unwrapped
            # one frame per 20 ms of simulated time (real-time GIF at 50 fps, whatever dt)
            if frames and u.state.t < frames[-1]["t"] + 0.02 - 1e-9:
                return
            frames.append({"t": u.state.t, "keypoints": u.keypoints()})
            if len(images) < GIF_MAX_FRAMES:
                images.append(env.render())

        evaluate_policy_episodes(model, vecnorm, cfg, 1, args.seed + idx, record=record)
        plots.save_gif(images, out_dir / "figures" / f"{name}.gif", fps=50)
        plots.stick_strip(
            frames,
            out_dir / "figures" / f"{name}_strip.png",
            f"{name} episode (seed {args.seed + idx}): "
            f"{eps[idx]['steps_completed']} steps, {eps[idx]['distance_m']:.2f} m",
            every=max(len(frames) // 15, 1),
        )
    reasons = Counter(e["end"] for e in eps)
    summary = {
        "episodes": eps,
        "steps_mean": steps.mean(),
        "steps_std": steps.std(),
        "steps_min": int(steps.min()),
        "distance_mean_m": dist.mean(),
        "distance_std_m": dist.std(),
        "distance_min_m": dist.min(),
        "ends": dict(reasons),
        "which": args.which,
        "baselines": baselines(),
    }
    if cfg.base_controller:  # the base controller alone on the same seeds
        base = evaluate_policy_episodes(None, None, cfg, args.episodes, args.seed)
        bs = np.array([e["steps_completed"] for e in base], dtype=float)
        bd = np.array([e["distance_m"] for e in base])
        summary["base_alone"] = {
            "controller": cfg.base_controller,
            "steps_mean": bs.mean(),
            "steps_std": bs.std(),
            "steps_min": int(bs.min()),
            "distance_mean_m": bd.mean(),
            "distance_std_m": bd.std(),
            "ends": dict(Counter(e["end"] for e in base)),
        }
    (out_dir / "evaluation.json").write_text(json.dumps(summary, indent=1, default=float) + "\n")
    print("| controller | completed steps (mean ± std, min) | distance [m] (mean ± std) | ends |")
    print("|---|---|---|---|")
    print(
        f"| PPO ({args.episodes} seeded episodes) | {steps.mean():.1f} ± {steps.std():.1f}, "
        f"min {int(steps.min())} | {dist.mean():.2f} ± {dist.std():.2f} | {dict(reasons)} |"
    )
    if "base_alone" in summary:
        b = summary["base_alone"]
        print(
            f"| base controller alone ({b['controller']}) | {b['steps_mean']:.1f} ± "
            f"{b['steps_std']:.1f}, min {b['steps_min']} | {b['distance_mean_m']:.2f} ± "
            f"{b['distance_std_m']:.2f} | {b['ends']} |"
        )
    for b in summary["baselines"]:
        print(
            f"| {b['controller']} (open loop) | {b['steps_completed']} | {b['distance_m']:.2f} | "
            f"{b['end']} |"
        )
    print(f"figures in {out_dir / 'figures'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
