"""The best candidate's hip speed from each start of a stop_feasibility.json (argv: JSON, PNG)."""

import json
import sys

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(src: str, dst: str) -> None:
    """Draw every start's best candidate; solid where it stood."""
    d = json.load(open(src))
    fig, ax = plt.subplots(figsize=(8, 4))
    for r in d["rows"]:
        v = np.array(r["best"]["v"], dtype=float)
        v[v >= 99] = np.nan  # periods after the candidate's episode ended
        t = np.arange(1, len(v) + 1) * 0.02
        what = "stops" if r["stood"] else "no stop found"
        ax.plot(t, v, lw=1, ls="-" if r["stood"] else ":",
                label=f"{r['hip_vy_m_s']:.2f} m/s (model {r['mode']}): {what}")  # fmt: skip
    ax.axhspan(-0.05, 0.05, color="0.85", zorder=0)
    ax.axvline(3.0, color="0.5", lw=0.8)
    ax.set_xlabel("time after the stop begins [s]")
    ax.set_ylabel("hip speed, per 20 ms period [m/s]")
    ax.set_ylim(-1.5, 2.5)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("best searched stop from the published walk's states "
                 "(grey: the rest band; line: 3 s)", fontsize=8)  # fmt: skip
    fig.tight_layout()
    from pathlib import Path

    from training.plumbing.outputs import save_figure  # the package's writer: no link followed

    save_figure(fig, Path(dst), dpi=110)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
