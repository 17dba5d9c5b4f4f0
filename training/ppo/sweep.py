r"""Multi-seed runs and hyperparameter sweeps of the PPO training, as Ray Tune trials.

    python -m training.ppo.sweep --config training/configs/ppo_walker.toml --seeds 0 1 2
    python -m training.ppo.sweep --config training/configs/ppo_scratch.toml --seeds 0 1 \\
        --grid learning_rate=1e-4,3e-4 --set total_timesteps=200000 [--ray-address HOST:PORT]

Every trial is one run of ``training.ppo.train`` (the same code and config as a single run:
``--config``, then ``--set`` values, then the trial's grid values and seed), in its own Tune
trial process with ``--cpus-per-trial`` CPUs (default 1) and one torch thread outside PPO's
updates (``--set update_threads=2`` with ``--cpus-per-trial 2``: one run at a time on a 2-core
machine, each alone). When training ends, the final network is
evaluated alone on ``--eval-episodes`` seeds from 10000 (the selection seeds: never used in
training, and not the final evaluation's seeds 0, 1, ... of ``training.evaluation.evaluate``);
the trial
reports completed steps and distance, with the run directory (model, best/, checkpoints/) as
its checkpoint. The trials run on a local Ray instance, or on a cluster with ``--ray-address``
(every node needs the project installed, at the same path when the config names files). The
results table is printed and written to ``results.csv`` in the sweep's directory
(``--out-dir/sweep_<name>``); Tune's own records of every trial are beside it.
"""

from __future__ import annotations

import io
import itertools
import os
import sys
from pathlib import Path

import numpy as np

from training.plumbing.common import CliParser, command, int_in
from training.plumbing.distributed import connect, shutdown
from training.plumbing.outputs import command_output, write_file

METRICS = ("steps_mean", "steps_min", "distance_mean_m", "env_steps", "train_wall_s")


def parse_assignments(items: list[str], flag: str, grid: bool) -> dict[str, list[str] | str]:
    """``key=value`` (``--set``) or ``key=v1,v2`` (``--grid``) items.

    The keys are PPOConfig's fields, or ``env.KEY`` / ``train_env.KEY`` for an entry of its
    env tables (``--grid env.dt=0.01,0.02``).
    """
    from dataclasses import fields

    from training.ppo.config import PPOConfig

    known = {f.name for f in fields(PPOConfig)}
    out: dict[str, list[str] | str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not value:
            raise ValueError(f"{flag} takes key=value, got {item!r}")
        table, dot, entry = key.partition(".")
        if dot and table in ("env", "train_env") and entry:
            pass  # an entry of a table: env.dt=0.02 (checked with the config)
        elif key not in known or key in ("seed", "out_dir", "resume", "progress", "env",
                                         "train_env"):  # fmt: skip
            raise ValueError(f"{flag}: {key!r} is not a settable PPOConfig field "
                             "(a table's entry: env.KEY or train_env.KEY)")  # fmt: skip
        out[key] = [v.strip() for v in value.split(",")] if grid else value.strip()
    return out


def evaluate_run(run: Path, episodes: int) -> dict[str, float]:
    """Steps and distance of the network a run publishes, alone on the selection seeds.

    With the env steps the run trained (it may have stopped by its own rule).

    They start at 10000: the final evaluation's seeds (0, 1, ...) stay unseen by the ranking.
    """
    from training.plumbing.rollouts import run_episodes
    from training.ppo.config import SELECTION_SEED_OFFSET
    from training.ppo.policy_io import load_policy, policy_actor

    policy, norm, cfg, _ = load_policy(run)  # the snapshot the run publishes
    trained = load_policy(run, "final")[3]["num_timesteps"]
    actor = policy_actor(policy, norm, cfg)
    seeds = range(SELECTION_SEED_OFFSET, SELECTION_SEED_OFFSET + episodes)
    eps = run_episodes(actor, cfg.env_kwargs(), seeds, cfg.env_id)
    steps = np.array([e["steps_completed"] for e in eps], dtype=float)
    return {
        "steps_mean": float(steps.mean()),
        "steps_min": float(steps.min()),
        "distance_mean_m": float(np.mean([e["distance_m"] for e in eps])),
        "env_steps": int(trained),
    }


def trial(config: dict) -> None:
    """One Tune trial: train_ppo with the trial's settings, evaluate, report with checkpoint."""
    import time

    import torch
    from ray import tune

    torch.set_num_threads(1)
    from training.ppo import train as train_ppo

    # Tune runs a trial in its own directory: relative paths (the config, files it names)
    # mean what they mean where the sweep was started, as in a serial run
    os.chdir(config["cwd"])

    out = Path(tune.get_context().get_trial_dir())
    earlier = sorted((out / "train_ppo").iterdir()) if (out / "train_ppo").is_dir() else []
    if earlier:  # a retried trial continues its run (refused by name if nothing to resume)
        print(f"trial: resuming {earlier[-1]}", flush=True)
        argv = ["--resume", str(earlier[-1]), "--progress", "false"]
    else:
        argv = ["--config", config["config"], "--seed", str(config["seed"]), "--progress", "false"]
        for key, value in config["settings"].items():
            table, dot, entry = key.partition(".")
            if dot:  # --env KEY=VALUE (a TOML value)
                argv += [f"--{table.replace('_', '-')}", f"{entry}={value}"]
            else:
                argv += [f"--{key.replace('_', '-')}", str(value)]
        argv += ["--out-dir", str(out)]
    t0 = time.time()
    train_ppo.main(argv)
    wall = time.time() - t0
    run = earlier[-1] if earlier else next((out / "train_ppo").iterdir())
    metrics = {**evaluate_run(run, config["eval_episodes"]), "train_wall_s": wall}
    tune.report(metrics, checkpoint=tune.Checkpoint.from_directory(run))


@command("sweep")
def main(argv: list[str] | None = None) -> int:
    """Run the sweep and print its results table."""
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, required=True, help="train_ppo TOML config")
    ap.add_argument(
        "--seeds", type=int_in(0, 2**31 - 1), nargs="+", default=[0], help="one trial per seed"
    )
    ap.add_argument("--grid", nargs="*", default=[], help="key=v1,v2: one trial per value")
    ap.add_argument("--set", nargs="*", default=[], dest="settings", help="key=value, all trials")
    ap.add_argument("--eval-episodes", type=int_in(1, 100_000), default=10)
    ap.add_argument("--ray-address", default="", help="HOST:PORT of a Ray cluster (else local)")
    ap.add_argument("--num-cpus", type=int, default=None, help="CPUs of a local Ray instance")
    ap.add_argument(
        "--cpus-per-trial",
        type=int_in(1, 1024),
        default=1,
        help="CPUs a trial holds, and the numba threads its env may use (2 with --set "
        "update_threads=2 env_threads=2: each run alone on 2 cores)",
    )
    ap.add_argument("--name", default="", help="sweep name (default: the config's stem)")
    ap.add_argument("--out-dir", type=Path, default=Path("runs"))
    a = ap.parse_args(argv)
    if not a.config.is_file():
        ap.error(f"--config: no such file {a.config}")
    if a.eval_episodes < 1:
        ap.error("--eval-episodes must be >= 1")
    try:
        fixed = parse_assignments(a.settings, "--set", grid=False)
        grid = parse_assignments(a.grid, "--grid", grid=True)
    except ValueError as e:
        ap.error(str(e))
    overlap = set(fixed) & set(grid)
    if overlap:
        ap.error(f"{sorted(overlap)} given to both --set and --grid")
    try:
        from ray import tune
    except ImportError:
        ap.error(
            "Ray Tune is not installed: pip install -e '.[distributed]' (in an environment of "
            "its own: Ray RLlib pins an older Gymnasium; docs/distributed.md)"
        )
    name = a.name or f"sweep_{a.config.stem}"
    if not name.replace("-", "").replace("_", "").replace(".", "").isalnum() or name[0] == ".":
        ap.error(f"--name {name!r}: letters, digits, '-', '_' and '.' only")
    storage = (a.out_dir / name).resolve()
    with command_output(storage, "sweep", whole=("tune", "results.csv")):
        pass  # claimed for the sweep (refused: another command's or a user's folder)
    combos = [dict(zip(grid, values, strict=True)) for values in itertools.product(*grid.values())]
    space = {
        "config": str(a.config.resolve()),
        "cwd": str(Path.cwd()),
        "seed": tune.grid_search(list(a.seeds)),
        "settings": tune.grid_search([{**fixed, **c} for c in combos]),
        "eval_episodes": a.eval_episodes,
    }
    connect(True, a.ray_address, a.num_cpus, threads=a.cpus_per_trial)
    try:
        tuner = tune.Tuner(
            tune.with_resources(trial, {"cpu": a.cpus_per_trial}),
            param_space=space,
            # trial folders named by their id: the default name lists the settings, with commas
            tune_config=tune.TuneConfig(trial_dirname_creator=lambda t: f"trial_{t.trial_id}"),
            run_config=tune.RunConfig(name="tune", storage_path=str(storage), verbose=1),
        )
        results = tuner.fit()
    finally:
        shutdown()
    rows = []
    for r in sorted(results, key=lambda r: (str(r.config["settings"]), r.config["seed"])):
        row = {"seed": r.config["seed"], **r.config["settings"]}
        if r.error is not None:
            row["error"] = f"{type(r.error).__name__}: {str(r.error).splitlines()[0]}"
        else:
            row.update({k: r.metrics.get(k) for k in METRICS})
            row["run_dir"] = r.checkpoint.path if r.checkpoint else ""
        rows.append(row)
    _write_table(rows, storage / "results.csv")
    print(f"sweep directory: {storage}")
    return 1 if any("error" in r for r in rows) else 0


def _write_table(rows: list[dict], path: Path) -> None:
    import csv

    cols = list(dict.fromkeys(k for r in rows for k in r))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    w.writerows(rows)
    write_file(path, buf.getvalue())
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for r in rows:
        cells = [
            f"{v:.3g}" if isinstance(v, float) else str(v) for v in (r.get(c, "") for c in cols)
        ]
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    sys.exit(main())
