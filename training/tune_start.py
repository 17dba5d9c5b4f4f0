"""Search the model controller's start phase from rest (the paper's Fig. 2 posture) by CMA-ES.

    python -m training.tune_start [--iterations 30] [--population 12] [--seeds 3]
        [--gains teacher_robust] [--out runs/tune_start]

The gait's gains stay as they are (``--gains``); the start phase's gains (those in
:data:`START_BOUNDS`, overriding the gait's until the first step is complete: see
:class:`training.model_controller.ModelController`) are searched with ``cma`` in
[0, 1]-scaled coordinates. Each candidate runs from ``--seeds`` noisy rest starts (the walking
task: 5 ms periods ending at each switch, default physics, strict checks, the env's reset
noise, seeds :data:`SEARCH_SEED_OFFSET` + i).

Why not score survival time: from rest, the longest-surviving motions stall (the hip stays
behind the stance toe, nothing moves on). The score here asks where the start *arrives*: the
state right after the first 4 -> 1 switch (the first step complete, the legs swapped) should
be one the gait itself passes through. Its cost is the distance from that state to the nearest
of the gait's own 4 -> 1 states (recorded from mid-stride walks of the same gains), plus 5 if
the gait then falls within :data:`HOLD_S`; a start that never completes its first step costs
10 plus the model switches it still lacked. A candidate's cost is its worst start's. The best
candidate is written to ``best_start.json`` (ship it as ``training/controllers/NAME.json`` and
use ``model:GAINS+NAME``), every candidate to ``history.csv``.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import cma
import numpy as np

from biped_constraint_env.observation import OBS_Q, OBS_QD
from training.common import progress
from training.model_controller import CONTROLLERS_DIR, ModelController, _read_gains

START_BOUNDS: dict[str, tuple[float, float]] = {
    "hy_swing": (-0.5, 0.1),
    "hy_lift": (-0.1, 0.3),
    "v1": (0.0, 3.0),
    "kv": (0.0, 10.0),
    "lift_dv": (0.0, 0.1),
    "heel_f": (-20.0, 0.0),
    "land": (0.2, 0.5),
    "flex": (0.3, 1.0),
    "foot_up": (0.0, 0.4),
    "kp3": (5.0, 50.0),
    "kd3": (1.0, 10.0),
    "sk1": (0.0, 0.6),
    "sk": (0.0, 0.2),
    "zc": (0.02, 0.1),
    "fmin": (3.0, 15.0),
}
"""The start phase's searched gains and their ranges (the rest are the gait's)."""
FIRST_STEP_LIMIT_S = 5.0
"""A start whose first step is not complete by then has failed [s]."""
HOLD_S = 2.0
"""After the first step, the gait must go on this long for the start to count in full [s]."""
SEARCH_SEED_OFFSET = 30_000
"""Rest starts of the search draw their noise from these seeds on (evaluation uses 0, 1, ...)."""
RATE_SCALE_S = 0.1
"""Rates count in the distance as the angle they move over this time [s]."""


def env_from_rest():
    """The walking task started at rest in the Fig. 2 posture (``start="rest"``)."""
    from biped_constraint_env.env import ConstrainedBipedEnv

    return ConstrainedBipedEnv(start="rest")


def _x(obs: np.ndarray) -> np.ndarray:
    """A state's coordinates in the distance: q1..q5 [rad], their rates times RATE_SCALE_S."""
    return np.concatenate([obs[OBS_Q][1:], RATE_SCALE_S * obs[OBS_QD][1:]])


def gait_switch_states(gains: dict, seeds=range(5), seconds: float = 10.0) -> np.ndarray:
    """The gait's states just after its 4 -> 1 switches (steps 2 on), from mid-stride walks."""
    from biped_constraint_env.env import ConstrainedBipedEnv

    env = ConstrainedBipedEnv()
    out = []
    for seed in seeds:
        ctl = ModelController(gains)
        obs, info = env.reset(seed=seed)
        side = info["stance_side"]
        while info["t"] < seconds:
            obs, _, term, trunc, info = env.step(ctl(obs))
            if term or trunc:
                break
            if info["stance_side"] != side:
                side = info["stance_side"]
                if info["steps_completed"] >= 2:
                    out.append(_x(obs))
    return np.array(out)


def first_step(env, ctl: ModelController, seed: int, reference: np.ndarray) -> dict:
    """One start from rest: whether and when the first step completed, and the cost."""
    obs, info = env.reset(seed=seed)
    reached = 0  # cycle positions passed (4 * steps + mode - 1)
    while info["t"] < FIRST_STEP_LIMIT_S:
        obs, _, term, _, info = env.step(ctl(obs))
        reached = max(reached, 4 * info["steps_completed"] + info["mode"] - 1)
        if term:
            return {"cost": 10.0 + (4 - min(reached, 4)), "t_first_s": None}
        if info["steps_completed"] >= 1:
            break
    else:
        return {"cost": 10.0 + (4 - min(reached, 4)), "t_first_s": None}
    t_first = info["t"]
    dist = float(np.min(np.linalg.norm(reference - _x(obs), axis=1)))
    fell = False
    while info["t"] < t_first + HOLD_S:
        obs, _, term, _, info = env.step(ctl(obs))
        if term:
            fell = True
            break
    return {"cost": dist + (5.0 if fell else 0.0), "t_first_s": t_first, "dist": dist}


def evaluate_candidate(gains, start_gains, seeds, reference) -> tuple[float, list[dict]]:
    """A candidate's cost (its worst start's) and the per-start results."""
    env = env_from_rest()
    runs = [
        first_step(env, ModelController(gains, start_gains=start_gains), s, reference)
        for s in seeds
    ]
    return max(r["cost"] for r in runs), runs


def _decode(z: np.ndarray) -> dict[str, float]:
    z = np.clip(z, 0.0, 1.0)
    pairs = zip(START_BOUNDS.items(), z, strict=True)
    return {k: lo + (hi - lo) * float(v) for (k, (lo, hi)), v in pairs}


def _encode(g: dict[str, float]) -> np.ndarray:
    return np.array([(g[k] - lo) / (hi - lo) for k, (lo, hi) in START_BOUNDS.items()])


def main(argv: list[str] | None = None) -> int:
    """Run the search; write best_start.json and history.csv."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=30)
    ap.add_argument("--population", type=int, default=12)
    ap.add_argument("--seeds", type=int, default=3, help="noisy rest starts per candidate")
    ap.add_argument("--gains", default="teacher_robust", help="the gait's gains (name or path)")
    ap.add_argument("--sigma", type=float, default=0.2, help="CMA-ES step in scaled units")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("runs/tune_start"))
    a = ap.parse_args(argv)
    if min(a.iterations, a.population, a.seeds) < 1:
        ap.error("--iterations, --population and --seeds must be >= 1")
    a.out.mkdir(parents=True, exist_ok=True)
    gains = _read_gains(a.gains, a.gains)
    t0 = time.time()
    print("recording the gait's own 4 -> 1 states (mid-stride walks)", flush=True)
    reference = gait_switch_states(gains)
    print(f"{len(reference)} reference states ({time.time() - t0:.0f} s)", flush=True)
    x0 = _encode({**gains, "hy_swing": START_BOUNDS["hy_swing"][0]})  # swing at once
    es = cma.CMAEvolutionStrategy(
        np.clip(x0, 0.05, 0.95),
        a.sigma,
        {"popsize": a.population, "seed": a.seed + 1, "bounds": [0, 1], "verbose": -9},
    )
    seeds = range(SEARCH_SEED_OFFSET, SEARCH_SEED_OFFSET + a.seeds)
    best = (np.inf, None, None)
    rows = []
    bar = progress(range(a.iterations), a.iterations, "start search")
    for it in bar:
        Z = es.ask()
        costs = []
        for z in Z:
            cand = _decode(np.asarray(z))
            cost, runs = evaluate_candidate(gains, cand, seeds, reference)
            costs.append(cost)
            rows.append({"iteration": it, "cost": cost, "runs": json.dumps(runs), **cand})
            if cost < best[0]:
                best = (cost, cand, runs)
        es.tell(Z, costs)
        if hasattr(bar, "set_postfix"):
            bar.set_postfix(best=f"{best[0]:.3f}", refresh=False)
        print(
            f"iteration {it}: best cost {min(costs):.3f}, so far {best[0]:.3f} "
            f"({time.time() - t0:.0f} s)",
            flush=True,
        )
    (a.out / "best_start.json").write_text(json.dumps(best[1], indent=1) + "\n")
    with open(a.out / "history.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"best cost {best[0]:.3f}: {json.dumps(best[2])}")
    print(f"wrote {a.out / 'best_start.json'} (ship as {CONTROLLERS_DIR}/NAME.json)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
