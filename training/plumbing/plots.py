"""Figures shared by the training scripts (matplotlib and Pillow, imported lazily)."""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from training.plumbing.outputs import save_figure, write_file
from training.plumbing.safe_files import read_csv

_MONITOR = re.compile(r"[0-9]{1,15}(\.[0-9]{1,6})?\.monitor\.csv")
"""The monitor files a run writes: START.monitor.csv, START.K.monitor.csv."""


def _int_list(text: str) -> list[int]:
    """A JSON list of at most 1000 integers (``imitation.csv``'s student steps)."""
    v = json.loads(text) if len(text) < 20_000 else None
    if not isinstance(v, list) or not v or len(v) > 1000 or any(type(x) is not int for x in v):
        raise ValueError("not a list of integers")
    return v


EVAL_COLUMNS = {"env_steps": int, "steps_mean": float, "steps_min": float, "return_mean": float}
"""The columns of a run's ``eval.csv`` that the figures read."""

SEGMENTS = (
    ("stance_toe", "stance_heel"),
    ("stance_heel", "stance_ankle"),
    ("stance_ankle", "stance_toe"),
    ("stance_ankle", "stance_knee"),
    ("stance_knee", "hip"),
    ("hip", "swing_knee"),
    ("swing_knee", "swing_ankle"),
    ("swing_heel", "swing_toe"),
    ("swing_ankle", "swing_heel"),
    ("swing_ankle", "swing_toe"),
)


def _mpl():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def stick_strip(frames: Sequence[dict], path: Path, title: str, every: int = 5) -> None:
    """Overlay stick figures every ``every`` control periods, like the paper's Fig. 6.

    ``frames``: per period, a dict with ``keypoints`` (name -> (y, z) [m]) and ``t`` [s].
    """
    plt = _mpl()
    fig, ax = plt.subplots(figsize=(10, 3.5))
    sel = list(frames[::every]) + ([frames[-1]] if len(frames) % every != 1 else [])
    cmap = plt.get_cmap("viridis")
    for k, fr in enumerate(sel):
        c = cmap(k / max(len(sel) - 1, 1))
        for a, b in SEGMENTS:
            pa, pb = fr["keypoints"][a], fr["keypoints"][b]
            ax.plot([pa[0], pb[0]], [pa[1], pb[1]], color=c, lw=1.2)
    ys = [p[0] for fr in sel for p in fr["keypoints"].values()]
    ax.axhline(0.0, color="k", lw=1)
    ax.set_xlim(min(ys) - 0.5, max(ys) + 0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("y [m]")
    ax.set_ylabel("z [m]")
    ax.set_title(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)


def mode_timeline(
    t: Sequence[float],
    modes: Sequence[int],
    path: Path,
    title: str,
    switches: Sequence[tuple[float, int, int]] = (),
) -> None:
    """Model number against time, like the paper's Fig. 7 (switch times marked)."""
    plt = _mpl()
    fig, ax = plt.subplots(figsize=(8, 2.8))
    ax.step(t, modes, where="post", color="tab:blue")
    for ts, _, _ in switches:
        ax.axvline(ts, color="tab:gray", lw=0.6, ls=":")
    ax.set_yticks([1, 2, 3, 4])
    ax.set_ylim(0.5, 4.5)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("model")
    ax.set_title(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)


def save_gif(images: Sequence[np.ndarray], path: Path, fps: float) -> None:
    """Write RGB frames as an animated GIF (whole, never through a link: :func:`write_file`).

    One 255-colour palette (median cut over up to eight frames spread through the clip) maps
    every frame, without dithering: about 5x faster than Pillow's adaptive palette per frame,
    which dominated an evaluation's wall time.
    """
    import io

    from PIL import Image

    if not images:
        return
    sample = images[:: max(1, len(images) // 8)][:8]
    palette = Image.fromarray(np.concatenate(sample, axis=0)).quantize(
        colors=255, method=Image.Quantize.MEDIANCUT
    )
    frames = [
        Image.fromarray(im).quantize(palette=palette, dither=Image.Dither.NONE) for im in images
    ]
    buf = io.BytesIO()
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:],
                   duration=max(int(1000 / fps), 20), loop=0)  # fmt: skip
    write_file(path, buf.getvalue())


def learning_curve(run: Path, path: Path) -> None:
    """Completed walking steps and return against env steps, from the monitors and eval.csv.

    With an imitation warm start (``imitation.csv``), a first panel shows the student's steps
    after each DAgger round against the demonstration samples collected so far.
    """
    plt = _mpl()
    imitation = run / "imitation.csv"
    names = (f for f in run.glob("*.monitor.csv") if _MONITOR.fullmatch(f.name))
    files = sorted((int(f.name.split(".")[0]), f) for f in names)
    mon, x = [], []
    for start, f in files:  # <start step>.monitor.csv of each session
        with open(f, "rb") as fh:
            if fh.read(1 << 16).count(b"\n") < 2:  # no header row: a session killed at its start
                continue
        rows = read_csv(f, {"r": float, "l": int, "steps_completed": int}, run, comment_lines=1)
        x.extend(start + np.cumsum([r["l"] for r in rows]))
        mon.extend(rows)
    x = np.array(x)
    rets = np.array([r["r"] for r in mon])
    steps = np.array([r["steps_completed"] for r in mon])
    fig, axes = plt.subplots(1, 3 if imitation.exists() else 2, figsize=(16, 3.8))
    if imitation.exists():
        im = read_csv(imitation, {"samples": int, "student_steps": _int_list}, run)
        n = [r["samples"] for r in im]
        st = [r["student_steps"] for r in im]
        axes[0].plot(n, [np.mean(v) for v in st], "o-", label="student, mean of 5 episodes")
        axes[0].plot(n, [np.min(v) for v in st], "x--", label="student, min")
        axes[0].set_xlabel("labelled samples (DART, then DAgger rounds)")
        axes[0].set_ylabel("completed walking steps")
        axes[0].set_title("imitation of the teacher", fontsize=9)
        axes[0].legend(fontsize=8)
        axes[0].grid(lw=0.3)
        axes = axes[1:]
    window = max(len(mon) // 200, 1)

    def smooth(y):
        return np.convolve(y, np.ones(window) / window, mode="valid")

    if len(mon):  # no training episode ended yet (a run of 0 env steps): no curve
        axes[0].plot(x[window - 1 :], smooth(steps), lw=1, label="training episodes (moving mean)")
        axes[1].plot(x[window - 1 :], smooth(rets), lw=1, label="training episodes (moving mean)")
    if (run / "eval.csv").exists():
        ev = read_csv(run / "eval.csv", EVAL_COLUMNS, run)
        ex = [r["env_steps"] for r in ev]
        lab = "evaluation (deterministic policy, seeded episodes)"
        axes[0].plot(ex, [r["steps_mean"] for r in ev], "o-", label=lab)
        axes[1].plot(ex, [r["return_mean"] for r in ev], "o-", label=lab)
    axes[0].set_ylabel("completed walking steps per episode")
    axes[1].set_ylabel("return")
    axes[0].set_title("PPO from the imitation result" if imitation.exists() else "PPO", fontsize=9)
    for ax in axes:
        ax.set_xlabel("env steps (PPO)")
        if ax.get_legend_handles_labels()[0]:  # nothing to label before an episode ends
            ax.legend(fontsize=8)
        ax.grid(lw=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def selection_curves(runs: Sequence[Path], labels: Sequence[str], path: Path) -> None:
    """Plot the periodic selection evaluations of several runs (each ``eval.csv``).

    ``runs``: run directories or the CSV files themselves. The mean and the fewest completed
    steps of each evaluation against env steps, one colour per run, or per group of runs
    labelled "GROUP, ..." (a line style per run of a group).
    """
    plt = _mpl()
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.8), sharey=True)
    groups = [label.split(",")[0] for label in labels]
    order = list(dict.fromkeys(groups))
    seen: dict[str, int] = {}
    for run, label, group in zip(runs, labels, groups, strict=True):
        ev = read_csv(Path(run) if Path(run).suffix == ".csv" else Path(run) / "eval.csv",
                      EVAL_COLUMNS)  # fmt: skip
        x = [r["env_steps"] / 1e6 for r in ev]
        style = ("-", "--", ":", "-.")[seen.get(group, 0) % 4]
        seen[group] = seen.get(group, 0) + 1
        colour = plt.get_cmap("tab20" if len(order) > 10 else "tab10")(order.index(group))
        for ax, key in zip(axes, ("steps_mean", "steps_min"), strict=True):
            ax.plot(x, [r[key] for r in ev], "o", ls=style, ms=3, color=colour,
                    label=label)  # fmt: skip
    axes[0].set_ylabel(
        "completed steps (selection episodes:\n6000 periods, 30 s at 5 ms, 120 s at 20 ms)",
        fontsize=8,
    )
    axes[0].set_title("mean of the selection episodes", fontsize=9)
    axes[1].set_title("worst selection episode", fontsize=9)
    for ax in axes:
        ax.set_xlabel("env steps [millions]")
        ax.axhline(20, color="k", lw=0.6, ls=":")
        ax.grid(lw=0.3)
    axes[1].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def initiation_strip(frames: Sequence[dict], path: Path, title: str, every_s: float = 0.1) -> None:
    """The start from rest: stick figures, centre of mass and centre of pressure.

    Above: stick figures every ``every_s`` [s] with the centre of mass (dots) and the centre
    of pressure (triangles on the ground); below: their y against time.

    ``frames``: per control period, ``t`` [s], ``keypoints``, ``com`` (y, z) and ``cop`` (y).
    """
    plt = _mpl()
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(10, 6.5), height_ratios=[1.3, 1])
    cmap = plt.get_cmap("viridis")
    t_end = frames[-1]["t"]
    sel, next_t = [], 0.0
    for fr in frames:
        if fr["t"] >= next_t - 1e-9:
            sel.append(fr)
            next_t += every_s
    for fr in sel:
        c = cmap(fr["t"] / max(t_end, 1e-9))
        for a, b in SEGMENTS:
            pa, pb = fr["keypoints"][a], fr["keypoints"][b]
            ax.plot([pa[0], pb[0]], [pa[1], pb[1]], color=c, lw=1.0)
        ax.plot(*fr["com"], "o", color=c, ms=4)
        if np.isfinite(fr["cop"]):
            ax.plot(fr["cop"], -0.04, "^", color=c, ms=5)
    ax.axhline(0.0, color="k", lw=1)
    ax.set_aspect("equal")
    ax.set_ylabel("z [m]")
    ax.set_title(title, fontsize=9)
    t = np.array([fr["t"] for fr in frames])
    for key, label in (("com", "centre of mass"), ("cop", "centre of pressure")):
        y = np.array([fr[key][0] if key == "com" else fr[key] for fr in frames])
        bx.plot(t, y, label=label)
    for name, style in (("stance_heel", "k--"), ("stance_toe", "k:")):
        y = [fr["keypoints"][name][0] for fr in frames]
        bx.plot(t, y, style, lw=0.8, label=name.replace("_", " ") + " (current stance foot)")
    for fr0, fr1 in zip(frames, frames[1:], strict=False):
        if fr1["mode"] != fr0["mode"]:
            bx.axvline(fr1["t"], color="0.8", lw=0.6)
            bx.text(fr1["t"], bx.get_ylim()[1], f" {fr1['mode']}", fontsize=7, va="top")
    bx.set_xlabel("t [s] (grey lines: model switches, new model's number on top)")
    bx.set_ylabel("y [m]")
    bx.legend(fontsize=7, loc="upper left")
    bx.grid(lw=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
