"""Tune the model controller's gains by CMA-ES (``cma``): the gait's, or its start from rest.

    python -m training.controller.tune [--phase gait] [--iterations 10] [--population 24]
        [--cap 12] [--init gains.json] [--noise 0.5] [--out results/tune_mc] [--workers 2]
        [--ray | --ray-address HOST:PORT]
    python -m training.controller.tune --phase start [--iterations 30] [--population 12]
        [--seeds 3] [--gains teacher_robust] [--out runs/tune_start]

One search, two objectives. CMA-ES searches the tuned gains scaled to [0, 1] within their
bounds (:data:`BOUNDS` of the phase) and writes the best candidate seen and ``history.csv``
(one row per candidate) into ``--out``.

``--phase gait``: every candidate (a dict of :data:`~.model_controller.DEFAULT_GAINS`
overrides) runs through the env (default physics, strict, ``dt=0.005``,
``stop_at_switch=True``) from every start of :data:`STARTS` (mid-stride model-2 states:
turning rate about the stance toe and heel-up angle), until it falls or completes ``cap``
steps. With ``--noise`` the executed torques carry Gaussian noise of that std [N m] (seeded per
start, the same for every candidate): a gait that tolerates it is a better teacher for a
network, whose errors it then tolerates too. Score: the mean of the completed steps over the
starts, plus 0.2 x their minimum (a robust gait counts more than one lucky start); the best is
``best_gains.json``. The runs of one iteration are independent: ``--workers`` local
processes, or Ray tasks with ``--ray`` (:mod:`training.plumbing.distributed`), with the same
results in the same order.

``--phase start``: the gait's gains stay as they are (``--gains``); the start phase's gains
(:data:`START_BOUNDS`, overriding the gait's until the first step is complete: see
:class:`~.model_controller.ModelController`) are searched, each candidate from ``--seeds``
noisy rest starts (seeds :data:`SEARCH_SEED_OFFSET` + i). Survival time is not the score: from
rest, the longest-surviving motions stall (the hip stays behind the stance toe). The cost asks
where the start *arrives*: the state right after the first 4 -> 1 switch should be one the gait
itself passes through. It is the distance from that state to the nearest of the gait's own
4 -> 1 states (recorded from mid-stride walks of the same gains), plus 5 if the gait then falls
within :data:`HOLD_S`; a start that never completes its first step costs 10 plus the model
switches it still lacked. A candidate's cost is its worst start's; the best is
``best_start.json`` (ship it as ``training/controller/gains/NAME.json`` and use
``model:GAINS+NAME``).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import time
from collections.abc import Callable
from pathlib import Path

import cma
import numpy as np

from biped_constraint_env.observation import OBS_Q, OBS_QD
from training.controller.model_controller import (
    CONTROLLERS_DIR,
    DEFAULT_GAINS,
    ModelController,
    _read_gains,
    midstride_state,
    run_episode,
)
from training.plumbing.common import CliParser, command, progress
from training.plumbing.distributed import connect, run_tasks, shutdown
from training.plumbing.outputs import command_output
from training.plumbing.safe_files import read_json_object

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

    env = ConstrainedBipedEnv(dt=dt, physics={"stop_at_switch": True})
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


def gait_score(results) -> float:
    """Mean completed steps over the starts + 0.2 x the minimum."""
    steps = np.array([r[0] for r in results], dtype=float)
    return float(steps.mean() + 0.2 * steps.min())


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


def start_cost(gains, start_gains, seeds, reference) -> tuple[float, list[dict]]:
    """A candidate's cost (its worst start's) and the per-start results."""
    env = env_from_rest()
    runs = [
        first_step(env, ModelController(gains, start_gains=start_gains), s, reference)
        for s in seeds
    ]
    return max(r["cost"] for r in runs), runs


def search(
    bounds: dict[str, tuple[float, float]],
    x0: dict[str, float],
    costs: Callable[[list[dict[str, float]]], list[tuple[float, dict]]],
    a: argparse.Namespace,
    best_file: str,
) -> tuple[float, dict[str, float]]:
    """CMA-ES over ``bounds`` (scaled to [0, 1]) from ``x0``: the best (cost, candidate).

    ``costs(candidates)`` gives each candidate's (cost, record) at once (lower is better;
    the record goes into ``history.csv``). After every iteration the best candidate so far
    is written to ``a.out / best_file`` (through ``a.handle``, the command's output).
    """
    out = a.handle
    names = list(bounds)
    lo = np.array([bounds[n][0] for n in names])
    hi = np.array([bounds[n][1] for n in names])
    z0 = (np.clip([x0[n] for n in names], lo, hi) - lo) / (hi - lo)
    es = cma.CMAEvolutionStrategy(
        np.clip(z0, 0.05, 0.95), a.sigma,
        {"popsize": a.population, "bounds": [0, 1], "seed": a.seed + 1, "verbose": -9},
    )  # fmt: skip
    best: tuple[float, dict] = (np.inf, dict(x0))
    rows: list[dict] = []
    t0 = time.time()
    for it in progress(range(a.iterations), a.iterations, f"CMA-ES ({a.phase})"):
        zs = [np.asarray(z) for z in es.ask()]
        cands = [dict(zip(names, map(float, lo + z * (hi - lo)), strict=True)) for z in zs]
        results = costs(cands)
        es.tell(zs, [c for c, _ in results])
        for cand, (cost, record) in zip(cands, results, strict=True):
            rows.append({"iteration": it, "cost": cost, **record, **cand})
            if cost < best[0]:
                best = (cost, cand)
        print(f"iteration {it}: best cost {min(c for c, _ in results):.3f}, so far "
              f"{best[0]:.3f} ({time.time() - t0:.0f} s)", flush=True)  # fmt: skip
        out.write(best_file, json.dumps(best[1], indent=1) + "\n")
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
        out.write("history.csv", buf.getvalue())
    return best


def _gait_costs(a: argparse.Namespace, init: dict[str, float]):
    """The gait phase's objective: minus :func:`gait_score` over the starts, in parallel."""
    starts = STARTS[: a.starts]

    def costs(cands):
        gains = [{**init, **c} for c in cands]
        jobs = [(g, r, th, a.cap, 0.005, a.noise, k) for g in gains
                for k, (r, th) in enumerate(starts)]  # fmt: skip
        res = run_tasks(run_start, jobs, use_ray=a.ray, ray_address=a.ray_address,
                        workers=a.workers)  # fmt: skip
        per = [res[i * len(starts) : (i + 1) * len(starts)] for i in range(len(cands))]
        return [(-gait_score(r), {f"start{k}": x[0] for k, x in enumerate(r)}) for r in per]

    return costs


def _start_costs(a: argparse.Namespace, gains: dict[str, float]):
    """The start phase's objective: :func:`start_cost` from ``--seeds`` noisy rest starts."""
    t0 = time.time()
    print("recording the gait's own 4 -> 1 states (mid-stride walks)", flush=True)
    reference = gait_switch_states(gains)
    print(f"{len(reference)} reference states ({time.time() - t0:.0f} s)", flush=True)
    seeds = range(SEARCH_SEED_OFFSET, SEARCH_SEED_OFFSET + a.seeds)

    def costs(cands):
        out = [start_cost(gains, c, seeds, reference) for c in cands]
        return [(cost, {"runs": json.dumps(runs)}) for cost, runs in out]

    return costs


@command("tune", "the iterations done so far are kept in the --out folder")
def main(argv: list[str] | None = None) -> int:
    """``python -m training.controller.tune``: see the module docstring."""
    ap = CliParser(description=__doc__.split("\n")[0])
    ap.add_argument("--phase", choices=("gait", "start"), default="gait")
    ap.add_argument("--iterations", type=int, default=None, help="default: 10 gait, 30 start")
    ap.add_argument("--population", type=int, default=None, help="default: 24 gait, 12 start")
    ap.add_argument("--sigma", type=float, default=None, help="initial spread / range width "
                    "(default: 0.15 gait, 0.2 start)")  # fmt: skip
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="default: results/tune_mc (gait), "
                    "runs/tune_start (start)")  # fmt: skip
    g = ap.add_argument_group("--phase gait")
    g.add_argument("--cap", type=int, default=12, help="steps at which a start counts as done")
    g.add_argument("--init", type=Path, help="gains JSON to start the search mean from")
    g.add_argument("--noise", type=float, default=0.0, help="torque noise std [N m]")
    g.add_argument("--workers", type=int, default=2, help="local processes (without Ray)")
    g.add_argument("--ray", action="store_true", help="run the starts as tasks on local Ray")
    g.add_argument("--ray-address", default="", help="HOST:PORT of a Ray cluster to run on")
    g.add_argument("--starts", type=int, default=len(STARTS), help="score the first N starts")
    s = ap.add_argument_group("--phase start")
    s.add_argument("--seeds", type=int, default=3, help="noisy rest starts per candidate")
    s.add_argument("--gains", default="teacher_robust", help="the gait's gains (name or path)")
    a = ap.parse_args(argv)
    gait = a.phase == "gait"
    for name, (dg, ds) in {"iterations": (10, 30), "population": (24, 12),
                           "sigma": (0.15, 0.2)}.items():  # fmt: skip
        if getattr(a, name) is None:
            setattr(a, name, dg if gait else ds)
    a.out = a.out or Path("results/tune_mc" if gait else "runs/tune_start")
    if a.iterations < 1 or a.population < 4 or a.cap < 1 or a.workers < 1 or a.sigma <= 0:
        ap.error("need iterations >= 1, population >= 4, cap >= 1, workers >= 1, sigma > 0")
    if not (np.isfinite(a.noise) and a.noise >= 0):
        ap.error(f"--noise must be >= 0, got {a.noise}")
    if not 1 <= a.starts <= len(STARTS) or a.seeds < 1:
        ap.error(f"--starts must be in 1..{len(STARTS)} and --seeds >= 1")
    if gait:
        init = {**DEFAULT_GAINS, **(read_json_object(a.init) if a.init else {})}
        bad = [k for k, v in init.items() if k not in DEFAULT_GAINS
               or isinstance(v, bool) or not isinstance(v, int | float)]  # fmt: skip
        if bad:
            ap.error(f"--init {a.init}: {bad[0]!r} is not a gain of the controller")
        connect(a.ray, a.ray_address)
        try:
            with command_output(a.out, "tune", keep_on_interrupt=True) as co:
                a.handle = co.dir()
                cost, best = search(BOUNDS, init, _gait_costs(a, init), a, "best_gains.json")
        finally:
            shutdown()
        print(f"best score {-cost:.2f}; gains in {a.out / 'best_gains.json'}")
        return 0
    gains = _read_gains(a.gains, a.gains)
    x0 = {**gains, "hy_swing": START_BOUNDS["hy_swing"][0]}  # swing at once
    with command_output(a.out, "tune", keep_on_interrupt=True) as co:
        a.handle = co.dir()
        cost, best = search(START_BOUNDS, x0, _start_costs(a, gains), a, "best_start.json")
    print(f"best cost {cost:.3f}; wrote {a.out / 'best_start.json'} (ship as "
          f"{CONTROLLERS_DIR}/NAME.json)")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
