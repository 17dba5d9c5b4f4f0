"""Automating the paper's trial and error: a cross-entropy search for an open-loop table.

    python -m training.optimize_open_loop [--iterations 300] [--population 512] [--restarts 3]

Searches the constant torques per model (4 x 5, within the env's +-150 N m) and the initial
model-1 posture (q1..q5) that maximise completed walking steps under **strict** physics (the
default simulator options: no point below the floor, no contact that has to pull). Score:
100 x completed steps + 10 x cycle position (4 x steps + model - 1, the furthest reached)
+ time inside the models [s]. Each population is one batch of the compiled simulator, with
the torque switching exactly at each model switch. The best table is written as an
``open_loop`` config (``best_open_loop.toml`` in the run directory; the committed copy is
``training/configs/open_loop_optimised.toml``) and re-checked through the env over 10 seeds of
its reset noise.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from biped_constraint_env import paper_biped
from biped_constraint_env.env import NOMINAL_POSTURE_RAD, TORQUE_LIMIT_NM
from biped_constraint_env.simulator import DEFAULT_OPTIONS, SimArrays, advance
from training.common import make_run_dir, parse_config, progress


@dataclass
class OptimiseConfig:
    """Settings of the search."""

    iterations: int = 300
    population: int = 512
    elite: int = 16  # a small elite keeps the rare candidates that reach further
    restarts: int = 3  # independent searches (different seeds)
    seconds: float = 10.0  # simulated time per candidate [s]
    torque_sd_nm: float = 70.0  # initial spread of the torques
    posture_sd_rad: float = 0.3  # initial spread of q1..q5
    seed: int = 0
    out_dir: Path = Path("runs")
    progress: bool = True


def score(X: np.ndarray, seconds: float, params=None, options=DEFAULT_OPTIONS):
    """Scores and completed steps of candidates X (n, 25): 20 torques then q1..q5."""
    params = params or paper_biped()
    n = len(X)
    sim = SimArrays(n)
    tables = np.clip(X[:, :20], -TORQUE_LIMIT_NM, TORQUE_LIMIT_NM).reshape(n, 4, 5)
    sim.q[:, 1:] = X[:, 20:25]
    sim.ist[:] = (1, 0, 0, 0)
    furthest = np.zeros(n)
    alive_s = np.zeros(n)
    for _ in range(int(round(seconds / 0.02))):
        advance(params, sim, tables, 0.02, options)
        furthest = np.maximum(furthest, 4 * sim.ist[:, 2] + sim.ist[:, 0] - 1)
        alive_s += 0.02 * (sim.status == 0)
        if (sim.status != 0).all():
            break
    steps = sim.ist[:, 2].copy()
    return 100 * steps + 10 * furthest + alive_s, steps


def search(cfg: OptimiseConfig, seed: int, show: bool):
    """One cross-entropy search; returns ((score, candidate, steps), history)."""
    rng = np.random.default_rng(seed)
    mu = np.concatenate([rng.normal(0, 30, 20), np.asarray(NOMINAL_POSTURE_RAD)[1:]])
    sd = np.concatenate([np.full(20, cfg.torque_sd_nm), np.full(5, cfg.posture_sd_rad)])
    floor = np.concatenate([np.full(20, 2.0), np.full(5, 0.01)])
    best = (-np.inf, None, 0)
    history = []
    for it in progress(range(cfg.iterations), cfg.iterations, f"search {seed}", show):
        X = mu + sd * rng.standard_normal((cfg.population, 25))
        X[:, :20] = np.clip(X[:, :20], -TORQUE_LIMIT_NM, TORQUE_LIMIT_NM)
        s, steps = score(X, cfg.seconds)
        el = np.argsort(-s)[: cfg.elite]
        if s[el[0]] > best[0]:
            best = (float(s[el[0]]), X[el[0]].copy(), int(steps[el[0]]))
        mu = 0.7 * mu + 0.3 * X[el].mean(0)
        sd = 0.7 * sd + 0.3 * X[el].std(0) + floor
        history.append((it, float(s.max()), int(steps.max())))
    return best, history


def robustness(x: np.ndarray, seeds: int = 10) -> list[int]:
    """Completed steps through the env, strict default preset, over its reset-noise seeds."""
    from training.open_loop import OpenLoopConfig, run

    cfg = OpenLoopConfig(
        preset="default",
        dt=0.002,
        max_periods=5000,
        gif=False,
        progress=False,
        torques=tuple(x[:20]),
        posture=(0.0, *x[20:25]),
    )
    return [
        run(cfg, record_frames=False, reset_seed=s, noise=0.01)["steps_completed"]
        for s in range(seeds)
    ]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the searches and write the best table."""
    cfg = parse_config(OptimiseConfig, argv, __doc__.splitlines()[0])
    rd = make_run_dir(cfg.out_dir, "optimize_open_loop", "ConstrainedBiped-v1", cfg.seed, cfg, argv)
    print(f"run directory: {rd}")
    results = []
    for r in range(cfg.restarts):
        best, history = search(cfg, cfg.seed + r, cfg.progress)
        results.append(
            {
                "seed": cfg.seed + r,
                "score": best[0],
                "steps": best[2],
                "x": best[1].tolist(),
                "history": history,
            }
        )
        print(f"search {cfg.seed + r}: best score {best[0]:.2f}, {best[2]} steps", flush=True)
    top = max(results, key=lambda d: d["score"])
    x = np.array(top["x"])
    x[:20] = np.clip(x[:20], -TORQUE_LIMIT_NM, TORQUE_LIMIT_NM)
    rob = robustness(x)
    toml = (
        "# Open-loop table found by training/optimize_open_loop.py under strict physics\n"
        f"# (search seed {top['seed']}, {top['steps']} steps from the exact posture;\n"
        f"# completed steps over 10 reset-noise seeds: {rob}).\n"
        'preset = "default"\ndt = 0.002\nmax_periods = 5000\n'
        f"torques = {json.dumps(x[:20].tolist())}\n"  # full precision: the steps are fragile
        f"posture = {json.dumps([0.0] + x[20:25].tolist())}\n"
    )
    (rd / "best_open_loop.toml").write_text(toml)
    (rd / "summary.json").write_text(
        json.dumps({"searches": results, "best": top, "robustness_steps_10_seeds": rob}, indent=1)
    )
    print(toml)
    print(f"steps over 10 reset-noise seeds: {rob}")
    print(f"run directory: {rd}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
