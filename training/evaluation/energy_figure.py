r"""Cost of transport against speed: a command policy's tracking rows beside the walkers.

    python -m training.evaluation.energy_figure --evaluations EVAL [EVAL ...]
        --labels NAME [NAME ...] --out results/energy

Each evaluation is the ``evaluation.json`` that ``training.evaluation.evaluate`` wrote. A
command policy's (one with the command protocol) gives a line: its mechanical cost of
transport at each tracked command (the motors' positive work at every physics step per weight
and distance), placed at the command; any other gives one point at its mean speed. The joint
damping's share of that work labels each. Writes ``energy.png`` and ``energy.md`` (the
table); reads only the files named, writes only ``--out``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from training.plumbing.common import CliParser, Refusal, command
from training.plumbing.outputs import command_output, write_file
from training.plumbing.safe_files import parse_json_object, read_bytes

MAX_FILE_BYTES = 64 * 2**20
"""Largest evaluation file read [bytes]."""
ANCHORS = (("Cornell Ranger", 0.28), ("ATRIAS", 1.0), ("DURUS", 1.61))
"""Mechanical costs of transport of walking robots, drawn for scale (Ranger: Bhounsule et al.
2014; ATRIAS: Hubicki et al., IEEE RAM 2018; DURUS: Reher et al. 2016)."""


def points(evaluation: Path) -> list[dict]:
    """(speed, cost of transport, damping share) rows of one evaluation.

    The tracking rows of a command protocol (speed: the command), else the evaluation's
    first result (speed: its mean speed). Refuses a file with no cost of transport of the
    motors' positive work (an evaluation written before it was measured).
    """
    d = parse_json_object(read_bytes(evaluation, MAX_FILE_BYTES, evaluation.parent), evaluation)
    rows = [r for r in d.get("command_protocol", []) if "command_m_s" in r]
    if rows:
        out = [{"speed_m_s": r["command_m_s"], "cot": r["cost_of_transport_mean"],
                "damping_share": r.get("damping_share_mean")} for r in rows]  # fmt: skip
    else:
        r = d["results"][0]
        if "cost_of_transport_abs_mean" not in r:
            raise Refusal(f"energy_figure: error: {evaluation}: no cost of transport of the "
                          f"motors' positive work (evaluate the policy again)")  # fmt: skip
        out = [{"speed_m_s": r["speed_mean_m_s"], "cot": r["cost_of_transport_mean"],
                "damping_share": r.get("damping_share_mean")}]  # fmt: skip
    return [p for p in out if p["cot"] is not None]


def figure(series: list[tuple[str, list[dict]]], path: Path) -> None:
    """Cost of transport against speed, one marker or line per evaluation."""
    from training.plumbing.outputs import save_figure
    from training.plumbing.plots import _mpl

    plt = _mpl()
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for label, pts in series:
        x = [p["speed_m_s"] for p in pts]
        y = [p["cot"] for p in pts]
        ax.plot(x, y, "o-" if len(pts) > 1 else "s", label=label)
    for name, value in ANCHORS:
        ax.axhline(value, color="grey", lw=0.8, ls="--")
        ax.text(0.02, value, f" {name} {value}", fontsize=7, va="bottom",
                transform=ax.get_yaxis_transform())  # fmt: skip
    ax.set_xlabel("speed [m/s] (a command policy: the commanded speed)")
    ax.set_ylabel("cost of transport (positive motor work / (m g d))")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)


def table(series: list[tuple[str, list[dict]]]) -> str:
    """The points as a markdown table."""
    out = ["| policy | speed [m/s] | cost of transport | damping's share |", "|---|---|---|---|"]
    for label, pts in series:
        for p in pts:
            share = "" if p["damping_share"] is None else f"{100 * p['damping_share']:.0f}%"
            out.append(f"| {label} | {p['speed_m_s']:.2f} | {p['cot']:.2f} | {share} |")
    return "\n".join(out) + "\n"


@command("energy_figure")
def main(argv: list[str] | None = None) -> int:
    """Read the evaluations, write the figure and the table into ``--out``."""
    ap = CliParser(description=__doc__.split("\n\n")[-1])
    ap.add_argument("--evaluations", nargs="+", type=Path, required=True)
    ap.add_argument("--labels", nargs="+", required=True)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    if len(args.labels) != len(args.evaluations):
        ap.error("give one label per evaluation")
    series = [(lab, points(ev)) for lab, ev in zip(args.labels, args.evaluations, strict=True)]
    with command_output(args.out, "energy_figure") as co:
        out = Path(co.dir().where())
        figure(series, out / "energy.png")
        write_file(out / "energy.md", table(series))
    print(table(series), end="")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
