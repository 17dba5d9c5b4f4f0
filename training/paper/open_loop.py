"""Open-loop baseline: constant torques per model (the paper's Table 2) through the env.

    python -m training.paper.open_loop [--config training/configs/open_loop_table2_paper.toml]
        [--flags]

The torque row of the *current* model is applied each control period. With the paper preset
(explicit Euler, switching at the 20 ms sample) the model changes only at a sample, so the
torque changes at the switch itself, as in the paper. With the accurate default preset the
switch is located inside the period; use a short control period (``--dt 0.002``) so that the
torque follows the switch within 2 ms, or set ``stop_at_switch = true`` (the env ends a period
at each model switch, so the new model's row applies from the switch itself, at any period).
A start other than rest can be given (``velocity``, ``mode``); ``noise_seeds = N`` re-runs the
table from N noisy starts (the env's reset-noise law, uniform +-``noise`` rad on q1..q5, seeds
0..N-1). Prints steps completed, distance, every model switch
and why the run ended; writes ``summary.json``, ``figures/strip.png`` (like the paper's
Fig. 6), ``figures/modes.png`` (Fig. 7) and ``figures/walk.gif`` into a fresh run directory.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np

import biped_constraint_env  # noqa: F401  (registers the env)
from biped_constraint_env.starts import NOMINAL_POSTURE_RAD, RESET_NOISE_SCALE_RAD, sample_initial_q
from training.plumbing.common import command, make_run_dir, parse_config, progress
from training.plumbing.outputs import write_file
from training.ppo.policy_io import json_text

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

    env_id: str = "ConstrainedBiped-v0"
    task: str = "paper"  # the env's task: rest start, 20 ms, the paper's numerics (preset below)
    preset: str = "paper"  # "paper" (the paper's numerics) or "default"
    table: str = "table2"  # a key of TABLES
    torques: tuple[float, ...] = ()  # 20 values [N m] (models 1-4 x joints 1-5): replaces `table`
    signs: tuple[int, ...] = (1, 1, 1, 1, 1)  # paper-to-project sign of each joint's torque
    posture: tuple[float, ...] = NOMINAL_POSTURE_RAD  # initial q [rad]
    velocity: tuple[float, ...] = ()  # initial qd [rad/s] (empty: at rest)
    mode: int = 1  # initial model
    dt: float = 0.02  # control period [s] (the paper's sample time)
    stop_at_switch: bool = False  # end a period at each model switch (exact torque switching)
    noise_seeds: int = 0  # also run this many noisy starts (seeds 0..N-1) and report their steps
    noise: float = RESET_NOISE_SCALE_RAD  # their noise scale [rad]
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
    """Roll out the table; returns the summary (and per-period records under ``"frames"``).

    With ``reset_seed`` the start is the config's, with the env's reset noise (uniform in
    [-noise, noise] rad on q1..q5, drawn from ``np.random.default_rng(reset_seed)``).
    """
    table = torque_table(cfg)
    q0 = np.asarray(cfg.posture, dtype=np.float64)
    qd0 = np.asarray(cfg.velocity if cfg.velocity else np.zeros(6), dtype=np.float64)
    if q0.shape != (6,) or qd0.shape != (6,):
        raise ValueError("posture and velocity must have 6 values (theta0, q1..q5)")
    if reset_seed is not None:
        q0 = sample_initial_q(np.random.default_rng(reset_seed), q0, noise)
    env = gym.make(
        cfg.env_id,
        task=cfg.task,
        preset=cfg.preset,
        dt=cfg.dt,
        physics={"stop_at_switch": cfg.stop_at_switch},
        start={"reset_noise_scale": 0.0},
        render_mode="rgb_array" if (record_frames and cfg.gif) else None,
        max_episode_steps=cfg.max_periods,
        termination={"time_limit_s": None},  # the scene's own limit: max_periods
    )
    obs, info = env.reset(seed=cfg.seed, options={"q": q0, "qd": qd0, "mode": cfg.mode})
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


def noisy_starts(cfg: OpenLoopConfig) -> list[dict]:
    """Steps, distance and end of the table from ``cfg.noise_seeds`` noisy starts."""
    quiet = dataclasses.replace(cfg, gif=False, progress=False)
    out = []
    for s in progress(range(cfg.noise_seeds), cfg.noise_seeds, "noisy starts", cfg.progress):
        r = run(quiet, record_frames=False, reset_seed=s, noise=cfg.noise)
        out.append({k: r[k] for k in ("steps_completed", "distance_m", "end_reason")} | {"seed": s})
    return out


@command("open_loop")
def main(argv: Sequence[str] | None = None) -> int:
    """Run the baseline and write its run directory."""
    cfg = parse_config(OpenLoopConfig, argv, __doc__.splitlines()[0])
    out = run(cfg)
    rd = make_run_dir(
        cfg.out_dir, "open_loop", cfg.env_id, cfg.seed, cfg, argv, module="training.paper.open_loop"
    ).path
    print(f"run directory: {rd}")
    from training.plumbing import plots

    name = "config torques" if cfg.torques else cfg.table
    title = f"{name}, preset {cfg.preset}, signs {tuple(cfg.signs)}"
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
    if cfg.noise_seeds:
        summary["noisy_starts"] = noisy_starts(cfg)
    write_file(rd / "summary.json", json_text(summary, indent=2))
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
    if cfg.noise_seeds:
        steps = [r["steps_completed"] for r in summary["noisy_starts"]]
        print(f"steps from {cfg.noise_seeds} noisy starts (+-{cfg.noise} rad): {steps}")
    print(f"run directory: {rd}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
