"""Evaluate several training runs on the same held-out seeds and print one table.

    python -m training.evaluation.compare RUN [RUN ...] [--which best final] [--episodes 10]
                                    [--scaffold CONFIG.toml] [--out runs/compare.json]
                                    [--curves runs/curves.png]

For the training seeds and ablations of a study: each run's ``best`` (selected on the
selection seeds during training) and/or ``final`` snapshot is evaluated, as ``python -m
training.evaluation.evaluate`` would (the run's own env options, the env's start distribution,
default
strict physics), on evaluation seeds 0, 1, ... that no training or selection used. A row
gives the run, what its config changes against the first run's, what is in the loop at run
time, and the complete steps (mean ± std, min) with the episodes' ends. ``--scaffold`` adds
the row of a config's run-time env with a zero network output (all that the PD law, the
reference and the env do without a network).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from biped_constraint_env.tasks import EPISODE_S
from training.plumbing.common import CliParser, command, int_in, refusals
from training.plumbing.outputs import write_file
from training.plumbing.rollouts import run_episodes, summarize
from training.ppo.policy_io import (
    SNAPSHOTS,
    available,
    find_snapshot,
    json_text,
    load_policy,
    load_state,
    policy_actor,
)

IGNORED = {"seed", "out_dir", "resume", "progress", "total_timesteps"}
"""Config fields that do not make a run a different recipe."""


def differences(cfg, base) -> str:
    """The config fields where ``cfg`` differs from ``base`` (``name=value``, comma-separated).

    A table's entries are compared one by one (``train_env.start={kind = "mixed"}``).
    """

    def flat(c) -> dict:
        out = {}
        for k, v in asdict(c).items():
            if isinstance(v, dict):
                out.update({f"{k}.{key}": x for key, x in v.items()})
            else:
                out[k] = v
        return out

    a, b = flat(cfg), flat(base)
    keys = [k for k in a if k not in IGNORED] + [k for k in b if k not in a]
    diff = [f"{k}={a.get(k)!r}" for k in keys if a.get(k) != b.get(k)]
    return ", ".join(diff) or "-"


def evaluate_run(run: Path, which: str, seeds: list[int], desc: str = "") -> dict:
    """One run's snapshot on ``seeds``: the summary of :func:`~.rollouts.summarize`.

    ``desc``: label of a progress bar over the episodes (none when empty).
    """
    policy, norm, cfg, state = load_policy(run, which)
    start = cfg.evaluation_start()
    cfg = replace(cfg, env={**cfg.env, "start": start})
    eps = run_episodes(
        policy_actor(policy, norm, cfg), cfg.env_kwargs(), seeds, cfg.env_id, desc=desc,
        episode_s=EPISODE_S,
    )  # fmt: skip
    row = summarize(f"{run.name} ({which})", eps)
    row.update(num_timesteps=int(state.get("num_timesteps", 0)), start=start)
    return row


def scaffold_row(config: Path, seeds: list[int]) -> dict:
    """The run-time env of ``config`` with a zero network output, on ``seeds``."""
    from training.plumbing.common import parse_config
    from training.ppo.config import PPOConfig

    cfg = parse_config(PPOConfig, ["--config", str(config)], "")
    amap = cfg.action_map()

    def zero(obs):
        return amap(np.zeros((1, 5)), obs[None, :])[0]

    eps = run_episodes(zero, cfg.env_kwargs(), seeds, cfg.env_id, episode_s=EPISODE_S)
    row = summarize(f"zero network output ({config.name})", eps)
    row.update(
        run=str(config),
        which="-",
        training_seed="-",
        changes="network output 0",
        in_the_loop=cfg.in_the_loop().replace("network", "zero output", 1),
        selected_at="-",
    )
    return row


@command("compare_runs")
def main(argv=None) -> int:
    """Evaluate every run's snapshots; print the markdown table; write the JSON."""
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="*", type=Path)
    ap.add_argument("--scaffold", type=Path, default=None, help="a config: zero-output row")
    ap.add_argument("--which", nargs="+", default=["best", "final"], choices=sorted(SNAPSHOTS))
    ap.add_argument("--episodes", type=int_in(1, 100_000), default=10)
    ap.add_argument("--seed", type=int_in(0, 2**31 - 1), default=0, help="episode i: seed + i")
    ap.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    ap.add_argument("--curves", type=Path, default=None, help="plot the runs' eval.csv here")
    a = ap.parse_args(argv)
    with refusals(ap):
        return _compare(a)


def _compare(a: argparse.Namespace) -> int:
    """:func:`main` on parsed arguments."""
    from training.ppo.policy_io import read_config

    seeds = list(range(a.seed, a.seed + a.episodes))
    rows = [scaffold_row(a.scaffold, seeds)] if a.scaffold is not None else []
    base = read_config(a.runs[0]) if a.runs else None
    t0 = time.time()
    n_rows, k = len(a.runs) * len(a.which), 0
    for run in a.runs:
        cfg = read_config(run)
        for which in a.which:
            k += 1
            if not available(run, which):
                print(f"{run}: no {which} snapshot", flush=True)
                continue
            row = evaluate_run(run, which, seeds, desc=f"[{k}/{n_rows}] {run.name} {which}")
            steps = np.array([e["steps_completed"] for e in row["episodes"]])
            row.update(
                run=str(run),
                which=which,
                training_seed=cfg.seed,
                changes=differences(cfg, base),
                in_the_loop=cfg.in_the_loop(),
                selected_at=load_state(find_snapshot(run, which)).get("num_timesteps"),
            )
            rows.append(row)
            print(
                f"{run.name} {which}: {steps.mean():.1f} ± {steps.std():.1f}, min {steps.min()} "
                f"({row['ends']}; {time.time() - t0:.0f} s)",
                flush=True,
            )
    print(f"\nseeds {seeds[0]}-{seeds[-1]}, 30 s episodes, default strict physics:")
    print("| run | seed | snapshot (env steps) | changes | in the loop | complete steps | ends |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {Path(r['run']).name} | {r['training_seed']} | {r['which']} ({r['selected_at']}) "
            f"| {r['changes']} | {r['in_the_loop']} | {r['steps_mean']:.1f} ± "
            f"{r['steps_std']:.1f}, min {r['steps_min']} | {r['ends']} |"
        )
    if a.curves is not None and a.runs:
        from training.plumbing.plots import selection_curves

        labels = []
        for run in a.runs:
            cfg = read_config(run)
            changes = differences(cfg, base)
            labels.append(f"seed {cfg.seed}" + ("" if changes == "-" else f", {changes}"))
        selection_curves(a.runs, labels, a.curves)
        print(f"selection curves: {a.curves}")
    if a.out is not None:
        write_file(a.out, json_text({"seeds": seeds, "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
