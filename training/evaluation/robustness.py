"""The robustness protocol: success rates under pushes, reset noise, model error, sensor noise.

``python -m training.evaluation.evaluate RUN --robustness`` (or ``--controller model:NAME
--robustness``)
runs every condition of :func:`conditions` on the report seeds, in the batched env, from the
evaluation's start, and writes ``robustness.json`` and ``figures/robustness.png``: success (at
least 20 complete strict steps in 30 s) with its 95% interval against push size, and a panel of
the other conditions. Every perturbation is an env option (``perturbations``, identical in the
single and the batched env); the physics and its strict checks are the defaults.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from training.plumbing.outputs import save_figure

PUSH_IMPULSES_NS = (0.25, 0.5, 1.0, 1.5)
"""Push sizes [N s], each forward and backward. The hip's velocity changes by about 1.25 m/s
per N s (the joints are free during the impulse), so they span about 0.3-1.9 m/s; the measured
change is reported per row."""
PUSH_WINDOW_S = (0.5, 10.0)
"""One push per episode, at a time drawn uniformly in this window [s]."""


def conditions(reset_noise: float) -> list[tuple[str, str, dict]]:
    """(group, label, {part: its keys on top of the evaluation's}) of every condition."""
    out: list[tuple[str, str, dict]] = [("nominal", "nominal", {})]
    for p in PUSH_IMPULSES_NS:
        for sign, word in ((1, "forward"), (-1, "backward")):
            pert = {"push_impulse_ns": sign * p, "push_at_s": PUSH_WINDOW_S}
            out.append(("push", f"push {word} {p} N s", {"perturbations": pert}))
    for k in (3, 5):
        out.append(
            ("reset noise", f"reset noise {k}x", {"start": {"reset_noise_scale": k * reset_noise}})
        )
    for m in (0.1, 0.2):
        pert = {"mass_scale": (1 - m, 1 + m)}
        out.append(("model", f"link masses ±{m:.0%}", {"perturbations": pert}))
    for lo, hi in ((0.4, 0.6), (0.3, 0.7)):
        pert = {"friction_ratio": (lo, hi)}
        out.append(("model", f"K {lo}-{hi}", {"perturbations": pert}))
    for a, r in ((0.005, 0.05), (0.02, 0.2)):
        pert = {"obs_noise": (a, r)}
        out.append(("sensor", f"obs noise {a} rad, {r} rad/s", {"perturbations": pert}))
    return out


def run(make_actor, env_kwargs: dict, seeds, env_id: str, label: str) -> list[dict]:
    """Every condition's row (``make_actor()``: a fresh batch actor per condition)."""
    from training.plumbing.rollouts import batched_row

    rows = []
    from biped_constraint_env.settings import make_settings, with_keys

    noise = make_settings(**env_kwargs).start.reset_noise_scale
    todo = conditions(noise)
    for k, (group, name, extra) in enumerate(todo, 1):
        kw = env_kwargs
        for part, keys in extra.items():  # each part's keys on top of the evaluation's
            kw = with_keys(kw, part, **keys)
        row = batched_row(f"{label}, {name}", make_actor(), kw, seeds, env_id,
                          progress=f"[{k}/{len(todo)}] {name}")  # fmt: skip
        dv = [abs(v) for e in row["episodes"] for v in e.get("push_dv_m_s", [])]
        row.update(group=group, condition=name,
                   push_dv_mean_m_s=float(np.mean(dv)) if dv else None)  # fmt: skip
        rows.append(row)
    return rows


EPISODE_FIELDS = ("seed", "steps_completed", "distance_m", "end")
"""What ``robustness.json`` keeps of each episode (the rows keep their summaries)."""


def compact(rows: list[dict]) -> list[dict]:
    """The rows for ``robustness.json``: each episode as [seed, steps, distance, end]."""
    return [
        {**{k: v for k, v in r.items() if k != "episodes"},
         "episode_fields": list(EPISODE_FIELDS),
         "episodes": [[e[k] for k in EPISODE_FIELDS] for e in r["episodes"]]}
        for r in rows
    ]  # fmt: skip


def figure(rows: list[dict], path: Path, title: str) -> None:
    """Success against push size (forward, backward) and a panel of the other conditions."""
    from training.plumbing.plots import _mpl

    plt = _mpl()
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [1, 1.4]})
    nominal = next(r for r in rows if r["condition"] == "nominal")
    for word, color in (("forward", "tab:blue"), ("backward", "tab:red")):
        pts = [(0.0, nominal)] + [
            (float(r["condition"].split()[2]), r)
            for r in rows
            if r["group"] == "push" and word in r["condition"]
        ]
        x = [p for p, _ in pts]
        y = [100 * r["success"]["rate"] for _, r in pts]
        err = [
            [100 * max(0.0, r["success"]["rate"] - r["success"]["ci95"][0]) for _, r in pts],
            [100 * max(0.0, r["success"]["ci95"][1] - r["success"]["rate"]) for _, r in pts],
        ]
        a.errorbar(x, y, yerr=err, marker="o", capsize=3, color=color, label=f"push {word}")
    a.set_xlabel("push impulse at the hip [N s] (the hip's velocity changes ~1.25 m/s per N s)")
    a.set_ylabel("success [%] (≥ 20 steps in 30 s), 95% CI")
    a.set_ylim(-3, 103)
    a.legend(fontsize=8)
    a.set_title("pushes at a random time in 0.5-10 s")
    others = [r for r in rows if r["group"] != "push"]
    y = [100 * r["success"]["rate"] for r in others]
    err = [
        [100 * max(0.0, r["success"]["rate"] - r["success"]["ci95"][0]) for r in others],
        [100 * max(0.0, r["success"]["ci95"][1] - r["success"]["rate"]) for r in others],
    ]
    b.barh(range(len(others)), y, xerr=err, capsize=3, color="tab:gray")
    b.set_yticks(range(len(others)), [r["condition"] for r in others], fontsize=8)
    b.invert_yaxis()
    b.set_xlim(0, 103)
    b.set_xlabel("success [%], 95% CI")
    b.set_title("reset noise, model error, sensor noise")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def markdown(rows: list[dict]) -> str:
    """The rows as a markdown table: condition, success (95% CI), mean |hip dv|, ends."""
    from training.plumbing.stats import format_success

    out = [
        "| condition | success, 95% CI | hip velocity change [m/s] | ends |",
        "|---|---|---|---|",
    ]
    for r in rows:
        dv = "" if r.get("push_dv_mean_m_s") is None else f"{r['push_dv_mean_m_s']:.2f}"
        ends = ", ".join(f"{k} {v}" for k, v in sorted(r["ends"].items(), key=lambda x: -x[1]))
        out.append(f"| {r['condition']} | {format_success(r['success'])} | {dv} | {ends} |")
    return "\n".join(out)
