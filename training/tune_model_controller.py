"""Tune the model-based controller's gains by CMA-ES (``cma``) over many starts.

    python -m training.tune_model_controller [--iterations 10] [--population 24] [--cap 12]
        [--init gains.json] [--noise 0.5] [--out results/tune_mc] [--workers 2]
        [--ray | --ray-address HOST:PORT]

Every candidate (a dict of :data:`training.model_controller.DEFAULT_GAINS` overrides) runs
through the env (default physics, strict, ``dt=0.005``, ``stop_at_switch=True``) from every
start of :data:`STARTS` (mid-stride model-2 states: turning rate about the stance toe and
heel-up angle), until it falls or completes ``cap`` steps. With ``--noise`` the executed
torques carry Gaussian noise of that std [N m] (seeded per start, the same for every
candidate): a gait that tolerates it is a better teacher for a network, whose errors it then
tolerates too. Score: the mean of the completed steps over the starts, plus 0.2 x their
minimum (a robust gait counts more than one lucky start). CMA-ES searches the tuned gains
scaled to [0, 1] within :data:`BOUNDS` and writes ``best_gains.json`` (the best candidate
seen) and ``history.csv`` (one row per candidate) into ``--out``. The runs of one iteration are
independent: ``--workers`` local processes, or Ray tasks with ``--ray`` (training/distributed.py),
with the same results in the same order.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cma
import numpy as np

from training.common import progress
from training.distributed import connect, run_tasks, shutdown
from training.model_controller import (
    DEFAULT_GAINS,
    ModelController,
    midstride_state,
    run_episode,
)

BOUNDS: dict[str, tuple[float, float]] = {
    "kp": (60.0, 160.0),
    "kd": (10.0, 26.0),
    "emax": (0.3, 0.9),
    "land": (0.25, 0.5),
    "fb_v": (-0.2, 0.3),
    "v_des": (1.0, 2.6),
    "fb_y": (-0.6, 0.6),
    "blend": (0.05, 0.3),
    "flex": (0.4, 1.0),
    "knee_land": (0.0, 0.2),
    "foot_up": (0.1, 0.4),
    "sk": (0.0, 0.2),
    "sk1": (0.0, 0.6),
    "hy_lift": (-0.05, 0.25),
    "hy_swing": (-0.35, 0.1),
    "heel_f": (-20.0, 0.0),
    "toe_lift_f": (-40.0, -5.0),
    "kp3": (10.0, 50.0),
    "kd3": (2.0, 10.0),
    "fmin": (5.0, 15.0),
    "zc": (0.03, 0.1),
    "clear_y": (0.05, 0.3),
    "v1": (1.6, 2.8),
    "kv": (0.0, 10.0),
    "lift_dv": (0.0, 0.3),
}
"""The tuned gains and their search ranges (units as in DEFAULT_GAINS)."""

STARTS: tuple[tuple[float, float], ...] = (
    (-0.85, -0.2),
    (-0.9, -0.2),
    (-1.0, -0.2),
    (-1.05, -0.2),
    (-1.1, -0.2),
    (-1.15, -0.2),
    (-0.9, -0.15),
    (-1.05, -0.25),
    (-1.1, -0.15),
    (-0.95, -0.25),
)
"""(rate [rad/s], theta0 [rad]) of :func:`midstride_state` for every scored start."""


def run_start(
    gains: dict[str, float],
    rate: float,
    theta0: float,
    cap: int,
    dt: float = 0.005,
    noise_nm: float = 0.0,
    noise_seed: int = 0,
):
    """(completed steps, hip travel [m], termination reason) of one start, at most ``cap`` steps.

    ``noise_nm``: std of Gaussian noise on the executed torques [N m] (generator ``noise_seed``).
    """
    from biped_constraint_env.env import ConstrainedBipedEnv

    env = ConstrainedBipedEnv(dt=dt, stop_at_switch=True)
    ctl = ModelController(gains, env.params, env.options)
    if noise_nm > 0:
        rng = np.random.default_rng(noise_seed)
        limit = env.settings.action.torque_limit_nm
        base = ctl

        def ctl(obs):
            return np.clip(base(obs) + noise_nm * rng.standard_normal(5), -limit, limit)

    s = midstride_state(rate, theta0)
    opts = dict(q=s.q, qd=s.qd, mode=2)
    steps, dist, reason, _ = run_episode(env, ctl, opts, max_periods=int(60.0 / dt), cap=cap)
    return steps, dist, reason


def score(results) -> float:
    """Mean completed steps over the starts + 0.2 x the minimum."""
    steps = np.array([r[0] for r in results], dtype=float)
    return float(steps.mean() + 0.2 * steps.min())


def main(argv: list[str] | None = None) -> None:
    """``python -m training.tune_model_controller``: see the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--iterations", type=int, default=10)
    ap.add_argument("--population", type=int, default=24)
    ap.add_argument("--cap", type=int, default=12, help="steps at which a start counts as done")
    ap.add_argument("--init", type=Path, help="gains JSON to start the search mean from")
    ap.add_argument("--sigma", type=float, default=0.15, help="initial spread / range width")
    ap.add_argument("--noise", type=float, default=0.0, help="torque noise std [N m]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2, help="local processes (without Ray)")
    ap.add_argument("--ray", action="store_true", help="run the starts as tasks on local Ray")
    ap.add_argument("--ray-address", default="", help="HOST:PORT of a Ray cluster to run on")
    ap.add_argument("--starts", type=int, default=len(STARTS), help="score the first N starts")
    ap.add_argument("--out", type=Path, default=Path("results/tune_mc"))
    a = ap.parse_args(argv)
    if a.iterations < 1 or a.population < 4 or a.cap < 1 or a.workers < 1 or a.sigma <= 0:
        ap.error("need iterations >= 1, population >= 4, cap >= 1, workers >= 1, sigma > 0")
    if not (np.isfinite(a.noise) and a.noise >= 0):
        ap.error(f"--noise must be >= 0, got {a.noise}")
    if not 1 <= a.starts <= len(STARTS):
        ap.error(f"--starts must be in 1..{len(STARTS)}")
    starts = STARTS[: a.starts]
    connect(a.ray, a.ray_address)
    init = {**DEFAULT_GAINS, **(json.loads(a.init.read_text()) if a.init else {})}
    names = list(BOUNDS)
    lo = np.array([BOUNDS[n][0] for n in names])
    hi = np.array([BOUNDS[n][1] for n in names])
    x0 = (np.clip([init[n] for n in names], lo, hi) - lo) / (hi - lo)
    es = cma.CMAEvolutionStrategy(
        x0, a.sigma, {"popsize": a.population, "bounds": [0, 1], "seed": a.seed + 1, "verbose": -9}
    )
    a.out.mkdir(parents=True, exist_ok=True)
    best = (-np.inf, dict(init))
    rows = []
    header = ["iteration", "score", *[f"start{i}" for i in range(len(starts))], *names]
    try:
        for it in progress(range(a.iterations), a.iterations, "CMA-ES"):
            cands = [np.asarray(c) for c in es.ask()]
            gains = [
                {**init, **dict(zip(names, map(float, lo + c * (hi - lo)), strict=True))}
                for c in cands
            ]
            jobs = [
                (g, r, th, a.cap, 0.005, a.noise, k)
                for g in gains
                for k, (r, th) in enumerate(starts)
            ]
            res = run_tasks(
                run_start, jobs, use_ray=a.ray, ray_address=a.ray_address, workers=a.workers
            )
            per = [res[i * len(starts) : (i + 1) * len(starts)] for i in range(len(cands))]
            scores = np.array([score(r) for r in per])
            es.tell(cands, list(-scores))
            for g, r, sc in zip(gains, per, scores, strict=True):
                rows.append([it, sc, *[x[0] for x in r], *[g[n] for n in names]])
                if sc > best[0]:
                    best = (sc, g)
            print(f"iteration {it}: best {scores.max():.2f}, best so far {best[0]:.2f}", flush=True)
            (a.out / "best_gains.json").write_text(json.dumps(best[1], indent=1) + "\n")
            np.savetxt(
                a.out / "history.csv",
                np.array(rows),
                delimiter=",",
                header=",".join(header),
                comments="",
            )
    finally:
        shutdown()
    print(f"best score {best[0]:.2f}; gains in {a.out / 'best_gains.json'}")


if __name__ == "__main__":
    main()
