"""Open-loop baseline: constant torques per model (the paper's Table 2) through the env.

    python -m training.open_loop [--config training/configs/open_loop_table2_paper.toml] [--flags]

The torque row of the *current* model is applied each control period. With the paper preset
(explicit Euler, switching at the 20 ms sample) the model changes only at a sample, so the
torque changes at the switch itself, as in the paper. With the accurate default preset the
switch is located inside the period; use a short control period (``--dt 0.002``) so that the
torque follows the switch within 2 ms. Prints steps completed, distance, every model switch
and why the run ended; writes ``summary.json``, ``figures/strip.png`` (like the paper's
Fig. 6), ``figures/modes.png`` (Fig. 7) and ``figures/walk.gif`` into a fresh run directory.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np

import biped_constraint_env  # noqa: F401  (registers the env)
from biped_constraint_env.env import NOMINAL_POSTURE_RAD
from training.common import make_run_dir, parse_config, progress

TABLES: dict[str, np.ndarray] = {
    "table2": np.array(
        [
            [10.0, 120.0, 35.0, 80.0, 0.0],
            [40.0, 0.0, 30.0, -30.0, -5.0],
            [-120.0, -70.0, 55.0, -30.0, -10.0],
            [-120.0, -70.0, 55.0, -30.0, -10.0],
        ]
    ),
}
"""Torque tables [N m], a row per model (paper Table 2, in the paper's signs)."""
GIF_MAX_FRAMES = 400


@dataclass
class OpenLoopConfig:
    """Settings of one open-loop run (defaults: the paper's reading, Table 2)."""

    env_id: str = "ConstrainedBiped-v1"
    preset: str = "paper"  # "paper" (the paper's numerics) or "default"
    table: str = "table2"  # a key of TABLES
    torques: tuple[float, ...] = ()  # 20 values [N m] (models 1-4 x joints 1-5): replaces `table`
    signs: tuple[int, ...] = (1, 1, 1, 1, 1)  # paper-to-project sign of each joint's torque
    posture: tuple[float, ...] = NOMINAL_POSTURE_RAD  # initial model-1 q [rad]
    dt: float = 0.02  # control period [s] (the paper's sample time)
    max_periods: int = 500  # control periods at most (10 s at 20 ms)
    seed: int = 0
    out_dir: Path = Path("runs")
    gif: bool = True
    progress: bool = True


def torque_table(cfg: OpenLoopConfig) -> np.ndarray:
    """(4, 5) torques [N m] of the config: ``torques`` if given, else TABLES[table] * signs."""
    signs = np.asarray(cfg.signs, dtype=np.float64)
    if signs.shape != (5,) or not np.all(np.abs(signs) == 1):
        raise ValueError(f"signs must be five values of +1 or -1, got {cfg.signs!r}")
    if cfg.torques:
        t = np.asarray(cfg.torques, dtype=np.float64)
        if t.shape != (20,) or not np.all(np.isfinite(t)):
            raise ValueError(f"torques must be 20 finite values, got {len(cfg.torques)}")
        return t.reshape(4, 5) * signs
    if cfg.table not in TABLES:
        raise ValueError(f"table must be one of {sorted(TABLES)}, got {cfg.table!r}")
    return TABLES[cfg.table] * signs


def run(
    cfg: OpenLoopConfig,
    record_frames: bool = True,
    reset_seed: int | None = None,
    noise: float = 0.0,
) -> dict:
    """Roll out the table; returns the summary (and per-period records under ``"frames"``)."""
    table = torque_table(cfg)
    env = gym.make(
        cfg.env_id,
        preset=cfg.preset,
        dt=cfg.dt,
        reset_noise_scale=0.0,
        render_mode="rgb_array" if (record_frames and cfg.gif) else None,
        max_episode_steps=cfg.max_periods,
    )
    if reset_seed is None:
        obs, info = env.reset(seed=cfg.seed, options={"q": np.asarray(cfg.posture), "mode": 1})
    else:  # the env's own noisy start around the posture
        obs, info = env.reset(seed=reset_seed)
    u = env.unwrapped
    y0 = info["hip_y"]
    frames, images, switches, events = [], [], [], []
    reason, truncated = None, False
    for _ in progress(range(cfg.max_periods), cfg.max_periods, "open loop", cfg.progress):
        if record_frames:
            frames.append({"t": info["t"], "mode": info["mode"], "keypoints": u.keypoints()})
            if cfg.gif and len(images) < GIF_MAX_FRAMES:
                images.append(env.render())
        obs, _, terminated, truncated, info = env.step(table[info["mode"] - 1].astype(np.float32))
        switches.extend(info["switches"])
        events.extend(e for e in info["events"] if e[1] != "mode_switch")
        if terminated or truncated:
            reason = info["termination_reason"] if terminated else "time_limit"
            break
    if record_frames:
        frames.append({"t": info["t"], "mode": info["mode"], "keypoints": u.keypoints()})
    env.close()
    return {
        "preset": cfg.preset,
        "table": cfg.table,
        "signs": list(cfg.signs),
        "posture": list(cfg.posture),
        "dt": cfg.dt,
        "steps_completed": int(info["steps_completed"]),
        "distance_m": float(info["hip_y"] - y0),
        "t_end_s": float(info["t"]),
        "end_reason": reason,
        "switches": [list(s) for s in switches],
        "recorded_events": [list(e) for e in events],
        "frames": frames,
        "images": images,
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Run the baseline and write its run directory."""
    cfg = parse_config(OpenLoopConfig, argv, __doc__.splitlines()[0])
    out = run(cfg)
    rd = make_run_dir(cfg.out_dir, "open_loop", cfg.env_id, cfg.seed, cfg, argv)
    print(f"run directory: {rd}")
    from training import plots

    title = f"{cfg.table}, preset {cfg.preset}, signs {tuple(cfg.signs)}"
    plots.stick_strip(
        out["frames"],
        rd / "figures" / "strip.png",
        f"{title}: {out['steps_completed']} steps",
        every=max(len(out["frames"]) // 12, 1),
    )
    plots.mode_timeline(
        [f["t"] for f in out["frames"]],
        [f["mode"] for f in out["frames"]],
        rd / "figures" / "modes.png",
        title,
        out["switches"],
    )
    if cfg.gif:
        plots.save_gif(out["images"], rd / "figures" / "walk.gif", fps=1.0 / cfg.dt)
    summary = {k: v for k, v in out.items() if k not in ("frames", "images")}
    (rd / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(
        f"steps completed: {out['steps_completed']}   distance (hip): {out['distance_m']:.3f} m   "
        f"simulated: {out['t_end_s']:.3f} s"
    )
    for t, a, b in out["switches"]:
        print(f"  t = {t:8.4f} s   model {a} -> {b}")
    for t, name, terminal in out["recorded_events"]:
        print(
            f"  t = {t:8.4f} s   {name}{' (ended the run)' if terminal else ' (recorded, lenient)'}"
        )
    print(f"ended by: {out['end_reason']}")
    print(f"run directory: {rd}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
