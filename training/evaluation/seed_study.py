r"""A recipe's training seeds in one table, one figure and one summary.

    python -m training.evaluation.seed_study --runs RUN [RUN ...] --evaluations EVAL [EVAL ...]
        --labels "seed 200" ... --out results/NAME [--walk-rate 0.95]

Each run is a training run directory (its ``eval.csv``: the selection evaluations; its
``published.json`` and ``training_time.txt``: which snapshot it publishes and why, how it
ended; its checkpoint: the restart rule's restarts); each evaluation the ``evaluation.json``
that ``training.evaluation.evaluate RUN`` wrote of that run's published snapshot on the report
seeds. Writes ``seeds.md`` (a row per seed: how the run ended, env steps, wall time, the
restarts where a run made any, success on the report episodes with its 95% interval),
``summary.json`` (the fraction of seeds whose published policy walks at least ``--walk-rate``
of its report episodes, and the interquartile mean of the success rates with a 95% bootstrap
interval over the seeds, rliable's statistics) and ``curves.png`` (every seed's selection
evaluations). Reads only the files named; writes only ``--out``.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from training.plumbing.common import CliParser, command
from training.plumbing.outputs import command_output, write_file
from training.plumbing.safe_files import parse_json_object, read_bytes
from training.plumbing.stats import format_success, iqm_interval
from training.ppo.policy_io import json_text

MAX_FILE_BYTES = 64 * 2**20
"""Largest evaluation or run file read [bytes]."""

RUN_LINE = re.compile(r"PPO: (\d+) env steps, (\d+) s wall this session(?:; (.*))?")


def run_record(run: Path, evaluation: Path) -> dict:
    """One seed's row: how its run ended and its published snapshot's report success."""

    def read(path: Path) -> bytes:
        return read_bytes(path, MAX_FILE_BYTES, path.parent)

    result = parse_json_object(read(evaluation), evaluation)["results"][0]
    published = parse_json_object(read(run / "published.json"), run / "published.json")
    lines = read(run / "training_time.txt").decode().splitlines()
    sessions = [m.groups() for m in map(RUN_LINE.match, lines) if m]
    if not sessions:
        raise ValueError(f"{run}/training_time.txt: no 'PPO: N env steps, S s wall' line")
    ended = "stopped by its rule" if (sessions[-1][2] or "").startswith("stopped") else "budget"
    return {
        "env_steps": int(sessions[-1][0]),
        "wall_s": sum(int(s[1]) for s in sessions),
        "ended": ended,
        "restarts": restarts_of(run),
        "published": published.get("snapshot"),
        "success": result["success"],
        "steps_mean": result["steps_mean"],
        "speed_m_s": result["speed_mean_m_s"],
    }


def restarts_of(run: Path) -> list[int]:
    """The env steps at which the run's restart rule drew a new network (its checkpoint's)."""
    from training.ppo.callbacks import check_restarts
    from training.ppo.policy_io import available, load_state, open_snapshot

    if not available(run, "checkpoint"):
        return []
    state = load_state(open_snapshot(run, "checkpoint"))  # num_timesteps checked there
    return check_restarts(state.get("restarts", []), f"{run}: the checkpoint",
                          state["num_timesteps"])  # fmt: skip


def summarize(records: list[dict], walk_rate: float) -> dict:
    """The fraction of seeds that walk, and the IQM of success with its 95% interval."""
    rates = [r["success"]["rate"] for r in records]
    centre, lo, hi = iqm_interval(rates)
    walls = sorted(r["wall_s"] for r in records)
    mid = len(walls) // 2
    median = walls[mid] if len(walls) % 2 else 0.5 * (walls[mid - 1] + walls[mid])
    return {
        "seeds": len(records),
        "walking_seeds": sum(r >= walk_rate for r in rates),
        "walk_rate": walk_rate,
        "success_iqm": centre,
        "success_iqm_ci95": [lo, hi],
        "wall_s_median": median,
        "wall_s_max": walls[-1],
    }


def table(labels: list[str], records: list[dict]) -> str:
    """The seeds' markdown table."""
    restarted = any(r.get("restarts") for r in records)  # a column only where a run restarted
    rows = ["| seed | the run ended | env steps | wall | "
            + ("restarts (env steps) | " if restarted else "")
            + "published snapshot on the report seeds | steps, speed |",
            "|---|---|---|---|" + ("---|" if restarted else "") + "---|---|"]  # fmt: skip
    for label, r in zip(labels, records, strict=True):
        at = ", ".join(f"{t / 1e6:.1f}M" for t in r.get("restarts", [])) or "none"
        rows.append(
            f"| {label} | {r['ended']} | {r['env_steps'] / 1e6:.1f}M | {r['wall_s']} s | "
            + (f"{at} | " if restarted else "")
            + f"{format_success(r['success'])} | {r['steps_mean']:.1f}, "
            f"{r['speed_m_s']:.2f} m/s |"
        )
    return "\n".join(rows) + "\n"


@command("seed_study")
def main(argv: list[str] | None = None) -> int:
    """Write the seed study's table, summary and figure."""
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=Path, nargs="+", required=True, help="training run dirs")
    ap.add_argument("--evaluations", type=Path, nargs="+", required=True,
                    help="each run's evaluation.json (of its published snapshot)")  # fmt: skip
    ap.add_argument("--labels", nargs="+", help="one per run (default: the run's name)")
    ap.add_argument("--walk-rate", type=float, default=0.95, help="a walking seed's success")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    labels = a.labels or [r.name for r in a.runs]
    if not len(a.runs) == len(a.evaluations) == len(labels):
        ap.error("give as many --evaluations and --labels as --runs")
    records = [run_record(r, e) for r, e in zip(a.runs, a.evaluations, strict=True)]
    summary = summarize(records, a.walk_rate)
    from training.plumbing.plots import selection_curves

    with command_output(a.out, "seed_study") as co:
        out = Path(co.dir().where())
        write_file(out / "seeds.md", table(labels, records))
        runs = dict(zip(labels, records, strict=True))
        write_file(out / "summary.json", json_text({**summary, "runs": runs}))
        selection_curves(a.runs, labels, out / "curves.png")
    print(table(labels, records))
    print(f"{summary['walking_seeds']} of {summary['seeds']} seeds walk >= "
          f"{100 * a.walk_rate:.0f}% of their report episodes; IQM of success "
          f"{100 * summary['success_iqm']:.1f}% [{100 * summary['success_iqm_ci95'][0]:.1f}, "
          f"{100 * summary['success_iqm_ci95'][1]:.1f}]; wall median {summary['wall_s_median']} s, "
          f"slowest {summary['wall_s_max']} s")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
