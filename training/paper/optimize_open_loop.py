"""Automating the paper's trial and error: a CMA-ES search (``cma``) for an open-loop table.

    python -m training.paper.optimize_open_loop [--iterations 300] [--population 512]
        [--restarts 3]
    python -m training.paper.optimize_open_loop --start midstride  # start velocity searched too
    python -m training.paper.optimize_open_loop --ray [--ray-address HOST:PORT]  # on Ray

Searches the constant torques per model (4 x 5, within the env's +-150 N m) and the initial
state that maximise completed walking steps under **strict** physics (the
default simulator options: no point below the floor, no contact that has to pull). The start:
``rest``, the model-1 posture q1..q5 at rest (the paper's setting); ``midstride``, the
mid-stride start of the walking task (:func:`~biped_constraint_env.starts.midstride_start`:
model 2, leg A on its toe, turning forward) with its rate, heel angle and lean searched, plus
offsets on q1..q5. Score:
100 x completed steps + 10 x cycle position (4 x steps + model - 1, the furthest reached)
+ time inside the models [s]. The search is ``cma``'s CMA-ES over the variables scaled by
their initial spreads; each population is one batch of the compiled simulator, with
the torque switching exactly at each model switch. The best table is written as an
``open_loop`` config (``best_open_loop.toml`` in the run directory; the committed copy is
``training/configs/open_loop_optimised.toml``) and re-checked through the env, with
``stop_at_switch`` (the row changes at the switch itself, 20 ms periods), from the found start
and from 10 seeds of the env's reset noise around it.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from biped_constraint_env import paper_biped
from biped_constraint_env.actions import TORQUE_LIMIT_NM
from biped_constraint_env.simulator import DEFAULT_OPTIONS, SimArrays, advance
from biped_constraint_env.starts import NOMINAL_POSTURE_RAD, midstride_start, start_slots
from biped_constraint_env.state import ST_MODE, ST_STEPS
from training.plumbing.common import command, make_run_dir, parse_config, progress
from training.plumbing.distributed import connect, cpu_count, init_ray, run_tasks, shutdown
from training.plumbing.outputs import write_file
from training.ppo.policy_io import json_text


@dataclass
class OptimiseConfig:
    """Settings of the search."""

    iterations: int = 300
    population: int = 512
    restarts: int = 3  # independent searches (different seeds)
    seconds: float = 10.0  # simulated time per candidate [s]
    torque_sd_nm: float = 70.0  # initial spread of the torques
    posture_sd_rad: float = 0.3  # initial spread of q1..q5
    start: str = "rest"  # "rest" (posture searched) or "midstride" (v2's start, searched)
    seed: int = 0
    out_dir: Path = Path("runs")
    progress: bool = True
    ray: bool = False  # score each population in chunks, as Ray tasks on a local Ray instance
    ray_address: str = ""  # HOST:PORT of a Ray cluster to score them on


def start_state(x: np.ndarray, start: str) -> tuple[np.ndarray, np.ndarray, int]:
    """(q, qd, mode) of a candidate's start variables ``x[20:]``.

    "rest": q1..q5 (5 values); "midstride": rate, theta0, lean, then offsets on q1..q5 (8).
    """
    if start == "rest":
        return np.concatenate([[0.0], x[20:25]]), np.zeros(6), 1
    if start == "midstride":
        q, qd = midstride_start(min(x[20], 0.0), min(x[21], 0.0), x[22])
        q[1:] += x[23:28]
        return q, qd, 2
    raise ValueError(f"start must be 'rest' or 'midstride', got {start!r}")


def score(X: np.ndarray, seconds: float, params=None, options=DEFAULT_OPTIONS, start="rest"):
    """Scores and completed steps of candidates X (n, 20 torques + the start's variables)."""
    params = params or paper_biped()
    n = len(X)
    sim = SimArrays(n)
    tables = np.clip(X[:, :20], -TORQUE_LIMIT_NM, TORQUE_LIMIT_NM).reshape(n, 4, 5)
    modes = np.empty(n, np.int64)
    for i in range(n):
        sim.q[i], sim.qd[i], modes[i] = start_state(X[i], start)
    low = start_slots(params, options, sim, np.arange(n), modes)
    sim.status[low < -1e-9] = -1  # a start below the floor scores as a failure at t = 0
    first = modes - 1
    furthest = np.zeros(n)
    alive_s = np.zeros(n)
    for _ in range(int(round(seconds / 0.02))):
        advance(params, sim, tables, 0.02, options)
        furthest = np.maximum(furthest, 4 * sim.ist[:, ST_STEPS] + sim.ist[:, ST_MODE] - 1 - first)
        alive_s += 0.02 * (sim.status == 0)
        if (sim.status != 0).all():
            break
    steps = sim.ist[:, ST_STEPS].copy()
    return 100 * steps + 10 * furthest + alive_s, steps


def score_population(X: np.ndarray, cfg: OptimiseConfig):
    """:func:`score` of a population: one batch here, or one chunk per Ray CPU as Ray tasks.

    Every candidate is simulated independently, so the scores are the same either way.
    """
    if not (cfg.ray or cfg.ray_address):
        return score(X, cfg.seconds, start=cfg.start)
    init_ray(cfg.ray_address or None)
    jobs = [
        (chunk, cfg.seconds, None, DEFAULT_OPTIONS, cfg.start)
        for chunk in np.array_split(X, min(len(X), cpu_count()))
    ]
    parts = run_tasks(score, jobs, use_ray=True, ray_address=cfg.ray_address)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def search(cfg: OptimiseConfig, seed: int, show: bool, label: str = "", bar=None):
    """One CMA-ES search; returns ((score, candidate, steps), history).

    ``label`` names the search in the progress bar (e.g. "restart 2/3"), which also shows
    the best score and steps so far. ``bar``: a tqdm bar over the whole job (every restart's
    iterations, so its ETA is the job's) to advance; else one of this search's own.
    """
    import cma

    rng = np.random.default_rng(seed)
    if cfg.start == "rest":
        mu0, sd0 = np.asarray(NOMINAL_POSTURE_RAD)[1:], np.full(5, cfg.posture_sd_rad)
    else:  # the walking task's mean start: rate -1 rad/s, heel up 0.2 rad, lean 0.1 rad
        mu0 = np.array([-1.0, -0.2, 0.1, 0, 0, 0, 0, 0])
        sd0 = np.array([0.5, 0.1, 0.1, *np.full(5, cfg.posture_sd_rad)])
    mu = np.concatenate([rng.normal(0, 30, 20), mu0])
    sd = np.concatenate([np.full(20, cfg.torque_sd_nm), sd0])
    es = cma.CMAEvolutionStrategy(
        np.zeros(len(mu)), 1.0, {"popsize": cfg.population, "seed": seed + 1, "verbose": -9}
    )
    best = (-np.inf, None, 0)
    history = []
    own = bar is None
    if own:
        bar = progress(range(cfg.iterations), cfg.iterations, label or f"search {seed}", show)
    elif hasattr(bar, "set_description"):
        bar.set_description(label or f"search {seed}")
    for it in bar if own else range(cfg.iterations):
        Z = np.array(es.ask())
        X = mu + sd * Z
        X[:, :20] = np.clip(X[:, :20], -TORQUE_LIMIT_NM, TORQUE_LIMIT_NM)
        s, steps = score_population(X, cfg)
        es.tell(list(Z), list(-s))
        i = int(np.argmax(s))
        if s[i] > best[0]:
            best = (float(s[i]), X[i].copy(), int(steps[i]))
            if hasattr(bar, "set_postfix"):
                bar.set_postfix(best=f"{best[0]:.2f}", steps=best[2], refresh=False)
        history.append((it, float(s.max()), int(steps.max())))
        if not own and hasattr(bar, "update"):
            bar.update(1)
    return best, history


def open_loop_config(x: np.ndarray, start: str):
    """The ``open_loop`` config of candidate x: exact switching through the env, 20 ms periods."""
    from training.paper.open_loop import OpenLoopConfig

    q, qd, mode = start_state(x, start)
    return OpenLoopConfig(
        preset="default",
        dt=0.02,
        stop_at_switch=True,
        max_periods=1000,
        gif=False,
        progress=False,
        torques=tuple(x[:20]),
        posture=tuple(q),
        velocity=tuple(qd),
        mode=mode,
    )


def robustness(cfg, seeds: int = 10) -> tuple[dict, list[int]]:
    """Through the env: the run of an ``open_loop`` config from its start, then ``seeds`` noisy."""
    from training.paper.open_loop import noisy_starts, run

    exact = run(cfg, record_frames=False)
    exact = {k: exact[k] for k in ("steps_completed", "distance_m", "end_reason")}
    noisy = noisy_starts(dataclasses.replace(cfg, noise_seeds=seeds))
    return exact, [r["steps_completed"] for r in noisy]


_RUN: list[Path] = []


def _interrupted() -> str:
    if not _RUN:
        return "nothing was written"
    return f"{_RUN[0]} is incomplete (INCOMPLETE.txt says how far it got); run the command again"


def _job_bar(cfg: OptimiseConfig):
    """One progress bar over every restart's iterations (None without tqdm or progress)."""
    if not cfg.progress:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=cfg.restarts * cfg.iterations, unit=" iterations", mininterval=1.0)


@command("optimize_open_loop", _interrupted)
def main(argv: Sequence[str] | None = None) -> int:
    """Run the searches and write the best table."""
    cfg = parse_config(OptimiseConfig, argv, __doc__.splitlines()[0])
    connect(cfg.ray, cfg.ray_address)
    rd = make_run_dir(
        cfg.out_dir,
        "optimize_open_loop",
        "ConstrainedBiped-v0",
        cfg.seed,
        cfg,
        argv,
        module="training.paper.optimize_open_loop",
    ).path
    _RUN[:] = [rd]
    print(f"run directory: {rd}")
    results = []
    bar = _job_bar(cfg)
    try:
        for r in range(cfg.restarts):
            label = f"restart {r + 1}/{cfg.restarts} (seed {cfg.seed + r})"
            print(f"{label}: CMA-ES, {cfg.iterations} iterations", flush=True)
            best, history = search(cfg, cfg.seed + r, cfg.progress, label, bar)
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
    except KeyboardInterrupt:
        write_file(rd / "INCOMPLETE.txt", f"interrupted after {len(results)} of {cfg.restarts} "
                   "searches; no best_open_loop.toml was written\n")  # fmt: skip
        raise
    finally:
        shutdown()
        if bar is not None:
            bar.close()
    top = max(results, key=lambda d: d["score"])
    x = np.array(top["x"])
    x[:20] = np.clip(x[:20], -TORQUE_LIMIT_NM, TORQUE_LIMIT_NM)
    oc = open_loop_config(x, cfg.start)
    exact, rob = robustness(oc)
    toml = (
        "# Open-loop table found by training/paper/optimize_open_loop.py under strict physics\n"
        f"# (start {cfg.start!r}, search seed {top['seed']}, {top['steps']} steps in the search;\n"
        f"# through the env: {exact['steps_completed']} steps, {exact['distance_m']:.3f} m, "
        f"ended by {exact['end_reason']};\n"
        f"# completed steps over 10 reset-noise seeds: {rob}).\n"
        f'preset = "default"\ndt = {oc.dt}\nstop_at_switch = true\nmax_periods = {oc.max_periods}\n'
        f"torques = {json.dumps(x[:20].tolist())}\n"  # full precision: the steps are fragile
        f"posture = {json.dumps(list(oc.posture))}\n"
        f"velocity = {json.dumps(list(oc.velocity))}\nmode = {oc.mode}\n"
    )
    write_file(rd / "best_open_loop.toml", toml)
    write_file(
        rd / "summary.json",
        json_text(
            {"searches": results, "best": top, "env_run": exact, "robustness_steps_10_seeds": rob}
        ),
    )
    print(toml)
    print(f"through the env: {exact}")
    print(f"steps over 10 reset-noise seeds: {rob}")
    print(f"run directory: {rd}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
