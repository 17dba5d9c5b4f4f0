"""How far does the paper's Table 2 walk? A search over the paper's open choices.

    python -m training.paper.table2_study [--postures 64] [--seconds 10] [--out-dir runs]
                                    [--ray | --ray-address HOST:PORT]

Readings searched (all combinations): the 32 per-joint sign mappings of the paper's torques
onto ours; sampled model-1 postures (stance foot flat, swing foot flat in the air, every
point above the floor; the nominal posture first); the friction ratio K in {0.3, 0.5, 1.0};
the impact option ("paper", "plastic"); the numerics ("paper": explicit Euler at 20 ms,
switching at the sample, finite-difference J-dot, foot weight left out; "default":
error-controlled RK4_LIMEX, located events, exact J-dot, foot weight included); and strict
versus lenient end checks.
Table 2 is applied as a per-model torque table, so the torque changes exactly at each model
switch. Every option set's readings run in one batch of the compiled simulator, a Ray task
each with ``--ray`` (training/plumbing/distributed.py; the same result as the serial run). The best
strict and best
lenient readings get a local posture refinement (random search) and a sensitivity test
(completed steps under uniform posture noise of +-0.01 rad, 100 samples).

A step counts only when the cycle 1 -> 2 -> 3 -> 4 -> 1 completes with no body point below the
floor (always checked) and, in strict mode, no contact that has to pull.
Writes summary.json, readings.csv.gz and figures/ (histogram, end reasons) into a run directory.
"""

from __future__ import annotations

import csv
import gzip
import io
import itertools
import json
import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from biped_constraint_env import paper_biped
from biped_constraint_env.kinematics import link_angles
from biped_constraint_env.modes import EventCode
from biped_constraint_env.simulator import (
    DEFAULT_OPTIONS,
    PAPER_OPTIONS,
    SimArrays,
    SimState,
    advance,
    keypoints,
)
from biped_constraint_env.starts import NOMINAL_POSTURE_RAD
from biped_constraint_env.state import FS_ROOT, ST_STEPS
from training.paper.open_loop import TABLES
from training.plumbing.common import command, make_run_dir, parse_config
from training.plumbing.distributed import TasksFailed, connect, run_tasks, shutdown
from training.plumbing.outputs import save_figure, write_file
from training.ppo.policy_io import json_text

SIGNS = np.array(list(itertools.product((1, -1), repeat=5)), dtype=float)


@dataclass
class StudyConfig:
    """Settings of the Table 2 study."""

    postures: int = 64  # sampled model-1 postures (the nominal one included)
    seconds: float = 10.0  # simulated time per reading [s]
    refine_iterations: int = 150  # random-search iterations of the posture refinement
    seed: int = 0
    out_dir: Path = Path("runs")
    progress: bool = True
    ray: bool = False  # run the option sets as Ray tasks on a local Ray instance
    ray_address: str = ""  # HOST:PORT of a Ray cluster to run them on


def sample_postures(n: int, rng: np.random.Generator) -> np.ndarray:
    """Model-1 postures: stance foot flat, swing foot flat, all points >= 5 cm above the floor."""
    params = paper_biped()
    out = [np.array(NOMINAL_POSTURE_RAD)]
    while len(out) < n:
        q = np.zeros(6)
        q[1:5] = rng.uniform([-0.6, -0.2, -1.0, -1.4], [0.4, 0.8, 0.8, 0.0])
        q[5] = 0.0
        q[5] = -np.angle(np.exp(1j * link_angles(q)[5]))  # swing foot flat
        pts = keypoints(params, SimState(0.0, 1, 0, q, np.zeros(6)))
        z = [v[1] for k, v in pts.items() if not k.startswith("stance_") or k == "stance_knee"]
        if min(z) > 0.05:
            out.append(q)
    return np.array(out)


def run_batch(tables: np.ndarray, postures: np.ndarray, options, seconds: float, params=None):
    """Roll out each (table, posture) pair; returns steps, distance [m], end code per reading."""
    params = params or paper_biped()
    if not (isinstance(seconds, (int, float)) and np.isfinite(seconds) and seconds > 0):
        raise ValueError(f"seconds must be a finite number > 0, got {seconds!r}")
    n = len(tables)
    sim = SimArrays(n)
    sim.q[:] = postures
    sim.ist[:] = (1, 0, 0, 0)
    periods = int(round(seconds / 0.02))
    end = np.full(n, -1)
    for _ in range(periods):
        advance(params, sim, tables, 0.02, options)
        newly = (sim.status != 0) & (end == -1)
        for i in np.flatnonzero(newly):
            codes = [e.code for e in sim.events_of(int(i)) if e.terminal]
            end[i] = int(codes[0]) if codes else int(EventCode.NON_FINITE)
        if (sim.status != 0).all():
            break
    return sim.ist[:, ST_STEPS].copy(), sim.fst[:, FS_ROOT].copy(), end


def option_sets():
    """(name, SimOptions, friction K) for every numerics x strictness x K x impact combination."""
    for numerics, base in (("paper", PAPER_OPTIONS), ("default", DEFAULT_OPTIONS)):
        for strict in (True, False):
            for impact in ("paper", "plastic"):
                for K in (0.3, 0.5, 1.0):
                    yield (
                        f"{numerics}/{'strict' if strict else 'lenient'}/{impact}/K={K}",
                        base.replace(strict=strict, impact=impact),
                        K,
                    )


def refine(
    sign_row: np.ndarray,
    q0: np.ndarray,
    options,
    K: float,
    seconds: float,
    iters: int,
    rng: np.random.Generator,
):
    """Random search on the posture around q0 (batches of 64); returns (best q, best steps)."""
    import dataclasses

    params = dataclasses.replace(paper_biped(), friction_ratio=K)
    table = TABLES["table2"] * sign_row
    best_q, best = q0.copy(), run_batch(table[None], q0[None], options, seconds, params)[0][0]
    scale = 0.1
    for _ in range(iters // 64 + 1):
        cand = best_q + np.concatenate([np.zeros((64, 1)), rng.normal(0, scale, (64, 5))], axis=1)
        steps, _, _ = run_batch(np.repeat(table[None], 64, 0), cand, options, seconds, params)
        k = int(np.argmax(steps))
        if steps[k] > best:
            best, best_q = int(steps[k]), cand[k]
        scale *= 0.8
    return best_q, int(best)


@command("table2_study")
def main(argv: Sequence[str] | None = None) -> int:
    """Run the study and write its run directory."""
    import dataclasses

    cfg = parse_config(StudyConfig, argv, __doc__.splitlines()[0])
    connect(cfg.ray, cfg.ray_address)
    rng = np.random.default_rng(cfg.seed)
    postures = sample_postures(cfg.postures, rng)
    rd = make_run_dir(
        cfg.out_dir,
        "table2_study",
        "ConstrainedBiped-v0",
        cfg.seed,
        cfg,
        argv,
        module="training.paper.table2_study",
    ).path
    print(f"run directory: {rd}")
    tables = np.repeat(TABLES["table2"][None] * SIGNS[:, None, :], len(postures), axis=0)
    qs = np.tile(postures, (len(SIGNS), 1))
    sign_idx = np.repeat(np.arange(len(SIGNS)), len(postures))
    post_idx = np.tile(np.arange(len(postures)), len(SIGNS))
    summary = {"readings_per_option_set": len(qs), "option_sets": {}}
    sets = list(option_sets())
    jobs = [
        (tables, qs, opts, cfg.seconds, dataclasses.replace(paper_biped(), friction_ratio=K))
        for _, opts, K in sets
    ]
    try:
        batches = run_tasks(
            run_batch,
            jobs,
            use_ray=cfg.ray,
            ray_address=cfg.ray_address,
            desc="Table 2 study",
            show=cfg.progress,
        )
    except TasksFailed as e:  # keep the option sets that ran; name the failed ones
        print(e, file=sys.stderr)
        batches = e.results
        summary["failed_option_sets"] = {sets[i][0]: err for i, _, err in e.failures}
    finally:
        shutdown()
    rows = _tally(summary, sets, batches, qs, sign_idx, post_idx)
    for mode in ("strict", "lenient"):  # refinement and sensitivity of the best readings
        best = _refine_best(summary, sets, mode, cfg, rng)
        if best is not None:
            summary[f"best_{mode}"] = best
    text = io.StringIO()
    w = csv.writer(text)
    w.writerow(["option_set", "sign_index", "posture_index", "steps", "root_y_m", "end_code"])
    w.writerows(rows)
    write_file(rd / "readings.csv.gz", gzip.compress(text.getvalue().encode(), mtime=0))
    write_file(rd / "summary.json", json_text(summary))
    buf = io.BytesIO()
    np.save(buf, postures)
    write_file(rd / "postures.npy", buf.getvalue())
    _figures(summary, rd)
    print(f"{'option set':<34} {'>=1':>5} {'>=2':>5} {'>=4':>5} {'max':>4}  most common end")
    for name, v in summary["option_sets"].items():
        top = next(iter(v["ends"].items()))
        print(
            f"{name:<34} {v['readings_with_ge1_steps']:>5} {v['readings_with_ge2_steps']:>5} "
            f"{v['readings_with_ge4_steps']:>5} {v['max_steps']:>4}  {top[0]} ({top[1]})"
        )
    for mode in ("strict", "lenient"):
        print(f"best {mode}:", json.dumps(summary.get(f"best_{mode}")))
    print(f"run directory: {rd}")
    return 1 if "failed_option_sets" in summary else 0


def _tally(summary: dict, sets, batches, qs, sign_idx, post_idx) -> list[tuple]:
    """Each option set's counts, best reading and ends into ``summary``; the readings' rows."""
    rows = []
    for (name, _, _), batch in zip(sets, batches, strict=True):
        if batch is None:
            continue
        steps, root_y, end = batch
        ends = Counter(EventCode(int(e)).name.lower() if e >= 0 else "time_limit" for e in end)
        k = int(np.argmax(steps * 1000 + root_y))
        summary["option_sets"][name] = {
            "readings_with_ge1_steps": int((steps >= 1).sum()),
            "readings_with_ge2_steps": int((steps >= 2).sum()),
            "readings_with_ge4_steps": int((steps >= 4).sum()),
            "max_steps": int(steps.max()),
            "best": {
                "signs": SIGNS[sign_idx[k]].astype(int).tolist(),
                "posture": qs[k].round(6).tolist(),
                "steps": int(steps[k]),
                "end": ends
                and (EventCode(int(end[k])).name.lower() if end[k] >= 0 else "time_limit"),
            },
            "ends": dict(ends.most_common()),
        }
        rows += [(name, int(sign_idx[i]), int(post_idx[i]), int(steps[i]), float(root_y[i]),
                  int(end[i])) for i in range(len(qs))]  # fmt: skip
    return rows


def _refine_best(summary: dict, sets, mode: str, cfg, rng) -> dict | None:
    """The best ``mode`` ("strict"/"lenient") reading refined, and its steps under noise."""
    import dataclasses

    cands = [(v["max_steps"], n) for n, v in summary["option_sets"].items() if f"/{mode}/" in n]
    if not cands:
        return None
    steps_best, name = max(cands)
    entry = summary["option_sets"][name]
    opts, K = next((o, k) for n, o, k in sets if n == name)
    signs = np.array(entry["best"]["signs"], float)
    q_ref, s_ref = refine(signs, np.array(entry["best"]["posture"]), opts, K, cfg.seconds,
                          cfg.refine_iterations, rng)  # fmt: skip
    noisy = q_ref + np.concatenate([np.zeros((100, 1)), rng.uniform(-0.01, 0.01, (100, 5))], axis=1)
    table = TABLES["table2"] * signs
    params = dataclasses.replace(paper_biped(), friction_ratio=K)
    s_noisy, _, _ = run_batch(np.repeat(table[None], 100, 0), noisy, opts, cfg.seconds, params)
    return {
        "option_set": name,
        "signs": entry["best"]["signs"],
        "steps_before_refinement": steps_best,
        "refined_posture": q_ref.round(6).tolist(),
        "refined_steps": s_ref,
        "sensitivity_steps_under_0.01rad_noise": dict(sorted(Counter(s_noisy.tolist()).items())),
    }


def _figures(summary: dict, rd: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(summary["option_sets"])
    fig, ax = plt.subplots(figsize=(11, 4.5))
    x = np.arange(len(names))
    for k, key in enumerate(
        ("readings_with_ge1_steps", "readings_with_ge2_steps", "readings_with_ge4_steps")
    ):
        ax.bar(
            x + (k - 1) * 0.27,
            [summary["option_sets"][n][key] for n in names],
            0.27,
            label=key.replace("readings_with_", "")
            .replace("_steps", " steps")
            .replace("ge", ">= "),
        )
    ax.set_xticks(x, names, rotation=75, fontsize=7)
    ax.set_ylabel(f"readings (of {summary['readings_per_option_set']})")
    ax.set_title("Table 2: readings that complete walking steps")
    ax.legend()
    fig.tight_layout()
    save_figure(fig, rd / "figures" / "steps_by_option_set.png", dpi=110)
    total = Counter()
    for v in summary["option_sets"].values():
        total.update(v["ends"])
    fig, ax = plt.subplots(figsize=(7, 4))
    labels, counts = zip(*total.most_common(), strict=True)
    ax.barh(labels, counts)
    ax.set_xlabel("readings (all option sets)")
    ax.set_title("what ends the Table 2 walks")
    fig.tight_layout()
    save_figure(fig, rd / "figures" / "end_reasons.png", dpi=110)


if __name__ == "__main__":
    raise SystemExit(main())
