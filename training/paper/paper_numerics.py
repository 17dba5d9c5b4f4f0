"""The paper's numerics against an accurate reference, on the same Table 2 reading.

    python -m training.paper.paper_numerics [--summary runs/table2_study/<run>/summary.json]

Takes the best lenient reading of the Table 2 study (sign mapping, refined posture, K, impact
option; the values below are the committed study's, or read from ``--summary``) and runs it
(1) with the paper's numerics (explicit Euler at 20 ms, switching at the sample,
finite-difference J-dot, foot weight left out of F_L), (2) with an accurate reference (RK4,
64 substeps per 20 ms, located events, exact J-dot, same impact option and K), both lenient,
and (3) the reference with strict checks. Prints steps, switches and the force violations
each records, and plots the model against time for the three (figures/paper_vs_reference.png).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from biped_constraint_env import paper_biped
from biped_constraint_env.modes import EventCode
from biped_constraint_env.simulator import PAPER_OPTIONS, SimOptions, SimState, step
from training.paper.open_loop import TABLES
from training.plumbing.common import command, make_run_dir, parse_config
from training.plumbing.outputs import save_figure, write_file
from training.ppo.policy_io import json_text


@dataclass
class NumericsConfig:
    """The reading to compare (defaults: the committed study's best lenient reading)."""

    summary: str = ""  # a table2_study summary.json to take the reading from
    signs: tuple[int, ...] = (-1, -1, -1, -1, 1)
    posture: tuple[float, ...] = (0.0, -0.515985, 0.632644, 0.416777, -1.064883, 0.531446)
    friction_ratio: float = 1.0
    impact: str = "paper"
    seconds: float = 10.0
    seed: int = 0
    out_dir: Path = Path("runs")


def rollout(params, q0, table, options, seconds):
    """Per-period (t, model), switches and recorded force events of one run."""
    st = SimState(0.0, 1, 0, np.asarray(q0, float), np.zeros(6))
    trace, switches, events, end = [(0.0, 1)], [], [], "time_limit"
    for _ in range(int(round(seconds / 0.02))):
        res = step(params, st, table, 0.02, options)
        st = res.state
        trace.append((st.t, int(st.mode) + 4 * st.steps_completed))
        for e in res.events:
            if e.code == EventCode.MODE_SWITCH:
                switches.append((round(e.t, 5), e.mode_from, e.mode_to))
            else:
                events.append((round(e.t, 5), e.code.name.lower(), e.terminal))
        if res.terminated:
            end = res.termination.name.lower()
            break
    return {
        "steps": st.steps_completed,
        "switches": switches,
        "events": events,
        "end": end,
        "trace": trace,
    }


@command("paper_numerics")
def main(argv: Sequence[str] | None = None) -> int:
    """Run the three settings and write the comparison."""
    cfg = parse_config(NumericsConfig, argv, __doc__.splitlines()[0])
    if cfg.summary:
        best = json.loads(Path(cfg.summary).read_text())["best_lenient"]
        name = best["option_set"]
        cfg = dataclasses.replace(
            cfg,
            signs=tuple(best["signs"]),
            posture=tuple(best["refined_posture"]),
            friction_ratio=float(name.split("K=")[1]),
            impact=name.split("/")[2],
        )
    params = paper_biped(friction_ratio=cfg.friction_ratio)
    table = TABLES["table2"] * np.asarray(cfg.signs, float)
    reference = SimOptions(integrator="rk4", substeps=64, impact=cfg.impact, strict=False)
    runs = {
        "paper numerics (Euler 20 ms, at the sample, FD J-dot), lenient": rollout(
            params, cfg.posture, table, PAPER_OPTIONS.replace(impact=cfg.impact), cfg.seconds
        ),
        "reference (RK4 0.31 ms, located, exact J-dot), lenient": rollout(
            params, cfg.posture, table, reference, cfg.seconds
        ),
        "reference, strict": rollout(
            params, cfg.posture, table, reference.replace(strict=True), cfg.seconds
        ),
    }
    rd = make_run_dir(
        cfg.out_dir,
        "paper_numerics",
        "ConstrainedBiped-v0",
        cfg.seed,
        cfg,
        argv,
        module="training.paper.paper_numerics",
    ).path
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.5))
    for k, (label, r) in enumerate(runs.items()):
        t, m = zip(*r["trace"], strict=True)
        ax.step(
            t,
            np.array(m) + 0.06 * k,
            where="post",
            label=f"{label}: {r['steps']} steps, {r['end']}",
        )
    ax.set_xlabel("t [s]")
    ax.set_ylabel("cycle position (model + 4 x steps)")
    ax.set_title(f"Table 2, signs {cfg.signs}, K = {cfg.friction_ratio}, impact {cfg.impact}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, rd / "figures" / "paper_vs_reference.png", dpi=110)
    out = {k: {kk: vv for kk, vv in v.items() if kk != "trace"} for k, v in runs.items()}
    write_file(rd / "summary.json", json_text(out))
    for label, r in out.items():
        print(f"{label}: {r['steps']} steps, ended by {r['end']}")
        print(f"   switches: {r['switches']}")
        print(f"   force events recorded: {r['events']}")
    print(f"run directory: {rd}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
