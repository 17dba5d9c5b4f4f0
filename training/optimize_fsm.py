"""Tune the finite-state feedback controller by a cross-entropy search through the batched env.

    python -m training.optimize_fsm [--iterations 200] [--population 384] [--periods 750]

Each iteration runs one population of controller parameter vectors (layout:
``training.fsm_controller.PARAM_NAMES``) as one batch of the vector env (preset "fast", strict
physics, its reset noise freshly seeded every iteration), for up to ``periods`` control periods
of 20 ms. Score: 100 x completed steps + 20 x cycle position (the furthest model reached) +
``alive_weight`` x seconds inside the models + 10 x hip travel [m] (clipped below at -2 m). The
search starts from ``--init`` (a controller JSON) or from a hand-set guess
(:data:`INITIAL_GUESS`: swing the thigh forward, knee bent behind and straight ahead, feet
level). At the end the search mean and the best single candidate are
evaluated on 10 reset-noise seeds, with both presets; the better by mean completed steps is
written as ``controller.json`` (``training/controllers/fsm_cem.json`` is the committed copy).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from training.common import make_run_dir, parse_config, progress
from training.fsm_controller import N_PARAMS, PARAM_NAMES, load, save, torques

_M = range(1, 5)
INITIAL_GUESS: dict[str, float] = {
    **dict(zip((f"hip_target_m{i}" for i in _M), (0.4, 0.5, 0.3, -0.3), strict=True)),
    **dict(zip((f"knee_behind_m{i}" for i in _M), (-0.8, -0.1, -0.1, -0.3), strict=True)),
    **dict(zip((f"foot_behind_m{i}" for i in _M), (0.0, 0.15, 0.0, 0.0), strict=True)),
    **{f"stance_knee_m{i}": 0.05 for i in _M},
    **{f"ankle_ff_m{i}": 0.0 for i in _M},
    "hip_fb_y": 0.0,
    "hip_fb_v": 0.0,
    "kp_hip": 100.0,
    "kd_hip": 10.0,
    "kp_knee": 60.0,
    "kd_knee": 5.0,
    "kp_foot": 20.0,
    "kd_foot": 1.0,
    "kp_stance_knee": 100.0,
    "kd_stance_knee": 5.0,
    "ankle_fb_y": 0.0,
    "ankle_fb_v": 0.0,
    "phase_angle": 0.0,
    "ankle_fb_swing": 0.0,
    # the "ahead" targets start equal to the "behind" ones (no blend) ...
    **dict(zip((f"knee_ahead_m{i}" for i in _M), (-0.8, -0.1, -0.1, -0.3), strict=True)),
    **dict(zip((f"foot_ahead_m{i}" for i in _M), (0.0, 0.15, 0.0, 0.0), strict=True)),
    # ... and the stance-foot pitch PD starts off
    "kp_stance_foot": 0.0,
    "foot_target": -0.3,
    "kd_stance_foot": 0.0,
}
"""The search's starting mean (angles in rad, torques in N m, gains in N m/rad, N m s/rad)."""
EXTRAS = (
    "phase_angle",
    "ankle_fb_swing",
    *(f"knee_ahead_m{i}" for i in _M),
    *(f"foot_ahead_m{i}" for i in _M),
    "kp_stance_foot",
    "foot_target",
    "kd_stance_foot",
)
"""Parameters held at the guess when ``--basic true`` (per-model PD targets only)."""


def _spread(name: str) -> float:
    """Initial standard deviation of one parameter."""
    if name.startswith(("hip_target", "knee_", "phase_angle")):
        return 0.3
    if name.startswith(("foot_", "hip_fb")):
        return 0.15 if name.startswith("foot_") and name != "foot_target" else 0.3
    if name.startswith("stance_knee"):
        return 0.1
    if name.startswith(("ankle_ff", "ankle_fb")):
        return 15.0
    if name.startswith("kp_"):
        return 30.0
    return 3.0  # kd_


@dataclass
class FSMSearchConfig:
    """Settings of the search."""

    iterations: int = 200
    population: int = 384
    elite: int = 8
    periods: int = 750  # 15 s of simulated time per candidate
    spread: float = 1.0  # multiplies the initial standard deviations
    alive_weight: float = 2.0  # score per second inside the models
    init: str = ""  # start from this controller JSON instead of INITIAL_GUESS
    basic: bool = False  # hold EXTRAS fixed (the first stage from the hand-set guess)
    preset: str = "fast"  # the env preset PPO trains on (RK2 x 4)
    seed: int = 0
    out_dir: Path = Path("runs")
    progress: bool = True


def rollout(x: np.ndarray, periods: int, seed: int, preset: str = "fast", alive_weight=0.5):
    """Run parameter rows ``x`` (n, N_PARAMS) as one batch; returns (score, steps, hip travel)."""
    from biped_constraint_env.vector_env import ConstrainedBipedVectorEnv

    n = len(x)
    env = ConstrainedBipedVectorEnv(num_envs=n, preset=preset, max_episode_steps=None)
    obs, info = env.reset(seed=seed)
    y0 = info["hip_y"].copy()
    done = np.zeros(n, bool)
    steps, furthest, alive, hip = (np.zeros(n) for _ in range(4))
    for _ in range(periods):
        obs, _, term, _, info = env.step(torques(x, obs))
        live = ~done
        steps[live] = info["steps_completed"][live]
        furthest[live] = np.maximum(furthest[live], 4 * steps[live] + info["mode"][live] - 1)
        hip[live] = info["hip_y"][live] - y0[live]
        alive += 0.02 * live
        done |= term
        if done.all():
            break
    env.close()
    score = 100 * steps + 20 * furthest + alive_weight * alive + 10 * np.clip(hip, -2, None)
    return score, steps, hip


def search(cfg: FSMSearchConfig):
    """The cross-entropy search; returns (mean, best candidate, history)."""
    rng = np.random.default_rng(cfg.seed)
    mu = load(cfg.init) if cfg.init else np.array([INITIAL_GUESS[k] for k in PARAM_NAMES])
    sd = cfg.spread * np.array(
        [0.0 if cfg.basic and k in EXTRAS else _spread(k) for k in PARAM_NAMES]
    )
    floor = 0.02 * sd
    best, best_score, history = mu.copy(), -np.inf, []
    for it in progress(range(cfg.iterations), cfg.iterations, "CEM", cfg.progress):
        x = mu + sd * rng.standard_normal((cfg.population, N_PARAMS))
        s, steps, _ = rollout(x, cfg.periods, cfg.seed * 100_000 + it, cfg.preset, cfg.alive_weight)
        el = np.argsort(-s)[: cfg.elite]
        if s[el[0]] > best_score:
            best, best_score = x[el[0]].copy(), float(s[el[0]])
        mu = 0.7 * mu + 0.3 * x[el].mean(0)
        sd = 0.7 * sd + 0.3 * x[el].std(0) + floor
        history.append(
            {
                "iteration": it,
                "score_max": float(s.max()),
                "steps_max": int(steps.max()),
                "elite_steps_mean": float(steps[el].mean()),
            }
        )
    return mu, best, history


def evaluate(x: np.ndarray, seeds: int = 10, periods: int = 1000) -> dict:
    """Completed steps and hip travel over reset-noise seeds 0..seeds-1, per preset."""
    out = {}
    for preset in ("fast", "default"):
        # one batch: sub-env i is seeded 0 + i, as episode i of training.evaluate
        _, st, hip = rollout(np.repeat(x[None, :], seeds, axis=0), periods, 0, preset)
        steps = [int(v) for v in st]
        out[preset] = {"steps": steps, "steps_mean": float(st.mean()), "distance_m": hip.tolist()}
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Run the search and write the controller."""
    cfg = parse_config(FSMSearchConfig, argv, __doc__.splitlines()[0])
    rd = make_run_dir(cfg.out_dir, "optimize_fsm", "ConstrainedBiped-v0", cfg.seed, cfg, argv)
    print(f"run directory: {rd}", flush=True)
    mu, best, history = search(cfg)
    cands = {"mean": mu, "best": best}
    evals = {k: evaluate(v) for k, v in cands.items()}
    pick = max(
        evals, key=lambda k: (evals[k]["fast"]["steps_mean"], evals[k]["default"]["steps_mean"])
    )
    e = evals[pick]
    save(
        cands[pick],
        rd / "controller.json",
        f"training/optimize_fsm.py seed {cfg.seed}, {cfg.iterations} x {cfg.population}; search "
        f"{pick}; completed steps over reset-noise seeds 0-9: fast {e['fast']['steps']}, "
        f"default {e['default']['steps']}",
        {"steps_by_reset_seed_0_9": {k: v["steps"] for k, v in e.items()}},
    )
    (rd / "summary.json").write_text(
        json.dumps({"picked": pick, "evaluations": evals, "history": history}, indent=1) + "\n"
    )
    for k, v in evals.items():
        print(f"{k}: fast steps {v['fast']['steps']}, default steps {v['default']['steps']}")
    print(f"picked {pick}; controller: {rd / 'controller.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
