"""The command task's protocol: start, tracking, stop and restart, random sequences, pushes, slopes.

Every row runs its episodes at once in the batched env (``policy_batch_actor``), the
commands set between control periods with ``set_command`` as a joystick would (each row's
command a function of its time), on the report seeds, with the default strict physics:

* **start**: from the paper's rest posture, commanded ``START_COMMAND_M_S``: a success is an
  episode of at least 20 complete steps in its 30 s (the walking success);
* **tracking**: a constant command per row of ``TRACK_COMMANDS_M_S``: the mean over episodes of
  |stride speed - command| (a stride: two steps; strides that end after ``SETTLE_S``), and the
  episodes that ran 30 s;
* **stop**: walk at a command drawn in [0.3, 2.0] m/s for ``STOP_AT_S``, then 0: a success
  stands (hip speed < ``STAND_SPEED_M_S``, the period's mean) at some period within
  ``STOP_WITHIN_S`` and holds it from there for ``HOLD_S`` with a mean drift below the same
  speed (:func:`stands`); then the command is 1.0 m/s
  again: **restart**, a success takes at least ``RESTART_STEPS`` steps in the next 10 s with
  no termination;
* **sequence**: a new command uniform in [0, 2] m/s every U(2, 5) s over 30 s: a success is no
  termination;
* with ``--robustness``, **pushes** (an OSU-style table: hip Δv of ``PUSH_DV_M_S`` forward and
  backward, each episode at its own phase of the gait, shown in ``PUSH_PHASES`` bins,
  commanded 1.0 m/s: a success is no termination in the 10 s after the push),
  **slopes** (``SLOPES_DEG`` at 1.0 m/s: the walking success, from the policy's start and
  from mid-stride) and the **model's
  randomisation** and **sensor noise** (``MODEL_CONDITIONS`` at 1.0 m/s, each alone: the
  walking success).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from biped_constraint_env.settings import with_keys
from training.plumbing.rollouts import ENERGY_KEYS
from training.plumbing.rollouts import energy as rollout_energy
from training.plumbing.stats import MIN_STEPS, success

START_COMMAND_M_S = 1.0
TRACK_COMMANDS_M_S = (0.3, 0.6, 1.0, 1.5, 2.0)
SETTLE_S = 3.0
"""Tracking is measured on strides that end after this time [s]."""
STOP_AT_S = 5.0
STOP_WITHIN_S = 3.0
HOLD_S = 5.0
STAND_SPEED_M_S = 0.05
RESTART_STEPS = 4
SEQUENCE_S = 30.0
PUSH_DV_M_S = (0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6)
PUSH_PHASES = 10
SLOPES_DEG = (-5.0, -2.5, 0.0, 2.5, 5.0)


def run_commanded(act, env_kwargs: dict, seeds: Sequence[int], command: Callable, episode_s,
                  env_id: str = "ConstrainedBiped-v0",
                  hook: Callable | None = None) -> list[dict]:  # fmt: skip
    """Episodes of ``seeds`` under ``command(t (n,), k) -> (n,)`` [m/s], set before every period.

    Each episode starts at its command (``reset(options={"command": command(t=0, k=0)})``): with
    the joystick's ramp, the held command moves from there, not from a command the reset drew.
    Per episode: its steps, end, the hip's y and the time at every period, the step times, and
    the commands it ran under (lists, for the rows' measures). ``hook(core, live, step_t)``
    runs before every period (a push: it may change the rows' rates).
    """
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401

    kw = with_keys(env_kwargs, "termination", time_limit_s=episode_s)
    venv = gym.make_vec(env_id, num_envs=len(seeds), vectorization_mode="vector_entry_point",
                        **kw)  # fmt: skip
    n = len(seeds)
    first = np.broadcast_to(np.asarray(command(np.zeros(n), 0), dtype=float), (n,))  # t = 0
    obs, info = venv.reset(seed=[int(s) for s in seeds], options={"command": first})
    entry = venv.unwrapped.observation_names.index("command_m_s")
    live = np.ones(n, bool)
    hip = [[float(info["hip_y"][i])] for i in range(n)]
    ts = [[float(info["t"][i])] for i in range(n)]
    cmds: list[list[float]] = [[] for _ in range(n)]
    step_t: list[list[float]] = [[] for _ in range(n)]
    steps = np.zeros(n, np.int64)
    ends = [None] * n
    energy: list[dict] = [{} for _ in range(n)]
    k = 0
    while live.any():
        v = np.asarray(command(info["t"], k), dtype=float)
        held = venv.unwrapped.set_command(v)  # 0 inside the command's deadband
        if hook is not None:
            hook(venv.unwrapped.core, live, step_t)
        obs = obs.copy()
        obs[:, entry] = held  # the command's entry as the env now gives it
        tau = np.asarray(act(obs), dtype=np.float64)
        tau[~live] = 0.0
        obs, _, term, trunc, info = venv.step(tau)
        k += 1
        for i in np.flatnonzero(live):
            hip[i].append(float(info["hip_y"][i]))
            ts[i].append(float(info["t"][i]))
            cmds[i].append(float(v[i]))
            if info["steps_completed"][i] > steps[i]:
                steps[i] = info["steps_completed"][i]
                step_t[i].append(float(info["t"][i]))
            if term[i] or trunc[i]:
                live[i] = False
                ends[i] = info["termination_reason"][i] or "time_limit"
                energy[i] = {k: float(info[k][i]) for k in ENERGY_KEYS}
    params = venv.unwrapped.params
    weight = params.total_mass_kg * params.gravity_mps2
    venv.close()
    return [{"seed": int(s), "steps_completed": int(steps[i]), "end": ends[i],
             "hip_y": hip[i], "t": ts[i], "command": cmds[i], "step_t_s": step_t[i],
             **rollout_energy(energy[i], weight, hip[i][-1] - hip[i][0])}
            for i, s in enumerate(seeds)]  # fmt: skip


def period_speeds(ep: dict) -> tuple[np.ndarray, np.ndarray]:
    """(t at each period's end, the period's mean hip speed [m/s]).

    A period of no duration (an env step that ended at a contact switch at its start) has no
    speed and is left out: it would read as at rest (0 m/s) in the middle of a walk.
    """
    t, y = np.asarray(ep["t"]), np.asarray(ep["hip_y"])
    dt = np.diff(t)
    keep = dt > 0.0
    return t[1:][keep], np.diff(y)[keep] / dt[keep]


def stride_errors(ep: dict, command: float, settle_s: float = SETTLE_S) -> list[float]:
    """|stride speed - command| [m/s] of the strides (two steps) that end after ``settle_s``."""
    t, y = np.asarray(ep["t"]), np.asarray(ep["hip_y"])
    marks = ep["step_t_s"][::2]
    out = []
    for a, b in zip(marks, marks[1:], strict=False):
        if b <= settle_s:
            continue
        ya, yb = np.interp(a, t, y), np.interp(b, t, y)
        out.append(abs((yb - ya) / (b - a) - command))
    return out


def start_row(act, env_kwargs, seeds, env_id) -> dict:
    """From rest at 1.0 m/s: the walking success."""
    eps = run_commanded(act, {**env_kwargs, "start": "rest"}, seeds,
                        lambda t, k: np.full(len(t), START_COMMAND_M_S), 30.0, env_id)  # fmt: skip
    return {"row": "start from rest, 1.0 m/s", "success": success([e["steps_completed"]
                                                                   for e in eps]),
            "ends": _ends(eps)}  # fmt: skip


def tracking_rows(act, env_kwargs, seeds, env_id) -> list[dict]:
    """Constant commands: the mean stride-speed error after SETTLE_S, per command."""
    rows = []
    for c in TRACK_COMMANDS_M_S:
        eps = run_commanded(act, env_kwargs, seeds, lambda t, k, c=c: np.full(len(t), c), 30.0,
                            env_id)  # fmt: skip
        errs = [np.mean(e) for e in (stride_errors(ep, c) for ep in eps) if e]
        full = sum(ep["end"] == "time_limit" for ep in eps)
        cot = [ep["cost_of_transport"] for ep in eps if np.isfinite(ep["cost_of_transport"])]
        share = [ep["damping_share"] for ep in eps if np.isfinite(ep["damping_share"])]
        rows.append({"row": f"track {c} m/s", "command_m_s": c,
                     "cost_of_transport_mean": float(np.mean(cot)) if cot else math.nan,
                     "damping_share_mean": float(np.mean(share)) if share else math.nan,
                     "mean_abs_error_m_s": float(np.mean(errs)) if errs else math.nan,
                     "episodes_measured": len(errs), "ran_30s": full, "episodes": len(eps),
                     "ends": _ends(eps)})  # fmt: skip
    return rows


def stands(t: np.ndarray, v: np.ndarray, t0: float, end_t: float) -> tuple[bool, float]:
    """The stop test on the period-mean hip speeds ``v`` [m/s] at period ends ``t`` [s].

    A zero command from ``t0``: a success is at rest (|v| < STAND_SPEED_M_S) at some period
    within STOP_WITHIN_S, held from there for HOLD_S (every period below twice that speed,
    their mean below it), with the episode running (``end_t``: its last time) to
    STOP_WITHIN_S + HOLD_S after ``t0``. Returns (success, the hold's mean |v|: of the first
    such period that holds, else of the first at rest; inf where none is at rest).
    """
    ran = end_t >= t0 + STOP_WITHIN_S + HOLD_S - 1e-9
    calm = (t > t0) & (t <= t0 + STOP_WITHIN_S) & (np.abs(v) < STAND_SPEED_M_S)
    drift = math.inf
    for first in t[calm] if ran else ():
        hold = (t > first) & (t <= first + HOLD_S)
        d = float(np.abs(v[hold]).mean()) if hold.any() else math.inf
        drift = d if math.isinf(drift) else drift
        if hold.any() and np.all(np.abs(v[hold]) < 2 * STAND_SPEED_M_S) and d < STAND_SPEED_M_S:
            return True, d
    return False, drift


def stop_rows(act, env_kwargs, seeds, env_id) -> list[dict]:
    """Walk, stop (command 0), stand, restart at 1.0 m/s."""
    rng = np.random.default_rng(int(seeds[0]))
    walk = rng.uniform(0.3, 2.0, len(seeds))
    restart_at = STOP_AT_S + STOP_WITHIN_S + HOLD_S

    def command(t, k):
        return np.where(t < STOP_AT_S, walk, np.where(t < restart_at, 0.0, START_COMMAND_M_S))

    eps = run_commanded(act, env_kwargs, seeds, command, restart_at + 10.0, env_id)
    stood, restarted, drifts = [], [], []
    for ep in eps:
        t, v = period_speeds(ep)
        stand, drift = stands(t, v, STOP_AT_S, ep["t"][-1])
        stood.append(stand)
        drifts.append(drift)
        after = [s for s in ep["step_t_s"] if s > restart_at]
        restarted.append(stand and ep["end"] == "time_limit" and len(after) >= RESTART_STEPS)
    n = len(eps)
    return [
        {"row": "stop: at rest within 3 s, held 5 s", "success": _rate(sum(stood), n),
         "drift_m_s_mean": float(np.mean([d for d in drifts if math.isfinite(d)] or [math.nan])),
         "ends": _ends(eps)},
        {"row": "restart to 1.0 m/s from that rest", "success": _rate(sum(restarted), n)},
    ]  # fmt: skip


def sequence_row(act, env_kwargs, seeds, env_id) -> dict:
    """Random command sequences over 30 s: no termination."""
    rng = np.random.default_rng(int(seeds[0]) + 1)
    changes = [np.cumsum(rng.uniform(2.0, 5.0, 16)) for _ in seeds]
    values = rng.uniform(0.0, 2.0, (len(seeds), 17))

    def command(t, k):
        idx = np.array(
            [np.searchsorted(c, ti, side="right") for c, ti in zip(changes, t, strict=True)]
        )
        return values[np.arange(len(t)), idx]

    eps = run_commanded(act, env_kwargs, seeds, command, SEQUENCE_S, env_id)
    ok = sum(ep["end"] == "time_limit" for ep in eps)
    return {"row": "random command sequences, 30 s", "success": _rate(ok, len(eps)),
            "ends": _ends(eps)}  # fmt: skip


PUSH_SETTLE_S = 4.0
"""Pushes come at the first step phase reached after this time [s] (a settled gait)."""
PUSH_AFTER_S = 10.0
"""A pushed episode succeeds when it runs this long after its push [s]."""


class PhasePush:
    """Each row's hip push of ``dv`` [m/s] at its gait phase ``phase`` (in [0, 1) of a step).

    The phase of a step: the time since the last step completed over the last step's
    duration. The impulse is scaled so that the hip's forward velocity changes by ``dv`` with
    the current model's contacts held (:func:`~biped_constraint_env.perturbations.hip_impulse`,
    linear in the impulse).
    """

    def __init__(self, dv: np.ndarray, phase: np.ndarray):
        """Pushes of ``dv`` (n,) [m/s] (signed: > 0 forward) at ``phase`` (n,)."""
        self.dv, self.phase = dv, phase
        self.at = np.full(len(dv), math.inf)
        self.done = np.zeros(len(dv), bool)

    def __call__(self, core, live, step_t) -> None:
        """Push the rows whose phase has come (before the period)."""
        from biped_constraint_env.kinematics import nb_point_jacobian
        from biped_constraint_env.perturbations import HIP_LINK, hip_impulse
        from biped_constraint_env.state import FS_T, ST_MODE, ST_SIDE

        sim = core.sim
        for i in np.flatnonzero(live & ~self.done):
            t = sim.fst[i, FS_T]
            st = [s for s in step_t[i] if s > PUSH_SETTLE_S]
            if len(st) < 2:
                continue
            phase = (t - st[-1]) / (st[-1] - st[-2])
            if phase < self.phase[i]:
                continue
            params = core.perturb.params[i]
            mode, side = int(sim.ist[i, ST_MODE]), int(sim.ist[i, ST_SIDE])
            q = sim.q[i].copy()
            dq = hip_impulse(params, mode, side, q, (1.0, 0.0))  # per N s
            jac = nb_point_jacobian(params.chain(side).packed, q, HIP_LINK, 0.0)
            sim.qd[i] += (self.dv[i] / float(jac[0] @ dq)) * dq
            self.done[i] = True
            self.at[i] = t


def push_rows(act, env_kwargs, seeds, env_id) -> list[dict]:
    """The push table: every size and direction at PUSH_PHASES phases, commanded 1.0 m/s.

    Episode k of n is pushed at the phase (k + 1/2) / n: the gait has settled into its cycle
    by the push, so episodes pushed at one phase would repeat each other; n phases are n
    conditions. ``by_phase``: the success in each of PUSH_PHASES bins of the phase. A success
    runs PUSH_AFTER_S after its push with no termination (an episode never pushed fails).
    """
    rows = []
    n = len(seeds)
    phase = (np.arange(n) + 0.5) / n
    for sign, name in ((1.0, "forward"), (-1.0, "backward")):
        for dv in PUSH_DV_M_S:
            push = PhasePush(np.full(n, sign * dv), phase)
            eps = run_commanded(act, env_kwargs, seeds,
                                lambda t, k: np.full(len(t), START_COMMAND_M_S),
                                PUSH_SETTLE_S + 4.0 + PUSH_AFTER_S, env_id, hook=push)  # fmt: skip
            ok = [push.done[i] and (ep["end"] == "time_limit"
                                    or ep["t"][-1] >= push.at[i] + PUSH_AFTER_S)
                  for i, ep in enumerate(eps)]  # fmt: skip
            bins = np.minimum((phase * PUSH_PHASES).astype(int), PUSH_PHASES - 1)
            by_phase = [float(np.mean(np.asarray(ok)[bins == k])) for k in range(PUSH_PHASES)]
            rows.append({"row": f"push {name} {dv} m/s", "direction": name, "dv_m_s": dv,
                         "success": _rate(sum(ok), n), "by_phase": by_phase,
                         "ends": _ends(eps)})  # fmt: skip
    return rows


MODEL_CONDITIONS = (
    ("link masses ±10%", {"mass_scale": (0.9, 1.1)}),
    ("K 0.4-0.6", {"friction_ratio": (0.4, 0.6)}),
    ("sensor noise 0.005 rad, 0.05 rad/s", {"obs_noise": (0.005, 0.05)}),
)
"""The model's randomisation and the sensor noise of the robustness protocol, each alone."""


def walk_rows(act, env_kwargs, seeds, env_id, conditions, start=None) -> list[dict]:
    """The walking success at 1.0 m/s under each (label, perturbations) of ``conditions``.

    The rows of :func:`slope_rows` and :func:`model_rows`; a study's own conditions the same way.

    ``start``: the episodes' start (None: the policy's own, ``env_kwargs``'s).
    """
    rows = []
    for label, pert in conditions:
        kw = {**env_kwargs, "perturbations": {**(env_kwargs.get("perturbations") or {}), **pert}}
        if start is not None:
            kw["start"] = start
        eps = run_commanded(act, kw, seeds, lambda t, k: np.full(len(t), START_COMMAND_M_S),
                            30.0, env_id)  # fmt: skip
        rows.append({"row": f"{label}, 1.0 m/s",
                     "success": success([e["steps_completed"] for e in eps]),
                     "ends": _ends(eps)})  # fmt: skip
    return rows


def slope_rows(act, env_kwargs, seeds, env_id) -> list[dict]:
    """Slopes at 1.0 m/s: the walking success on each, from the policy's start, then mid-stride.

    The mid-stride rows measure the walk on the slope apart from the start on it (the rest
    posture, made for flat ground, leans back on a slope rising forward).
    """
    rows = []
    for start, where in ((None, ""), ("midstride", " from mid-stride")):
        slopes = [(f"slope {deg:+.1f} deg{where}", {"slope_rad": math.radians(deg)})
                  for deg in SLOPES_DEG]  # fmt: skip
        rows += walk_rows(act, env_kwargs, seeds, env_id, slopes, start)
    return rows


def model_rows(act, env_kwargs, seeds, env_id) -> list[dict]:
    """Masses, K and sensor noise (:data:`MODEL_CONDITIONS`) at 1.0 m/s: the walking success."""
    return walk_rows(act, env_kwargs, seeds, env_id, MODEL_CONDITIONS)


def push_figure(rows: list[dict], path) -> None:
    """Success against push size, one line per phase bin, forward and backward."""
    from training.plumbing.outputs import save_figure
    from training.plumbing.plots import _mpl

    plt = _mpl()
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
    for ax, name in zip(axes, ("forward", "backward"), strict=True):
        mine = [r for r in rows if r.get("direction") == name]
        x = [r["dv_m_s"] for r in mine]
        cmap = plt.get_cmap("viridis")
        for k in range(PUSH_PHASES):
            ax.plot(x, [100 * r["by_phase"][k] for r in mine], "-", color=cmap(k / PUSH_PHASES),
                    lw=1, alpha=0.8, label=f"phase {k / PUSH_PHASES:.1f}")  # fmt: skip
        ax.plot(x, [100 * r["success"]["rate"] for r in mine], "k-o", lw=2, label="all phases")
        ax.set_title(f"{name} hip push at 1.0 m/s", fontsize=9)
        ax.set_xlabel("hip velocity change [m/s]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("episodes that run 10 s on [%]")
    axes[1].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    save_figure(fig, path)


def _rate(k: int, n: int) -> dict:
    from training.plumbing.stats import wilson_interval

    lo, hi = wilson_interval(k, n)
    return {"successes": k, "episodes": n, "rate": k / n, "ci95": (lo, hi), "min_steps": MIN_STEPS}


def _ends(eps) -> dict:
    from collections import Counter

    return dict(Counter(ep["end"] for ep in eps))


def run_protocol(act, env_kwargs: dict, seeds: Sequence[int], env_id: str) -> list[dict]:
    """The protocol's rows (the module docstring), in order."""
    return [start_row(act, env_kwargs, seeds, env_id),
            *tracking_rows(act, env_kwargs, seeds, env_id),
            *stop_rows(act, env_kwargs, seeds, env_id),
            sequence_row(act, env_kwargs, seeds, env_id)]  # fmt: skip


def markdown(rows: list[dict]) -> str:
    """The rows as a markdown table."""
    from training.plumbing.stats import format_success

    out = ["| row | result | ends |", "|---|---|---|"]
    for r in rows:
        if "success" in r:
            res = format_success(r["success"])
            if r.get("drift_m_s_mean") is not None:
                res += f"; drift {r['drift_m_s_mean']:.3f} m/s"
        else:
            err = r["mean_abs_error_m_s"]
            err = math.nan if err is None else err
            cot = r.get("cost_of_transport_mean")
            res = (f"mean abs(stride speed - command) {err:.3f} m/s "
                   f"({r['episodes_measured']} episodes with strides after 3 s; "
                   f"{r['ran_30s']}/{r['episodes']} ran 30 s); cost of transport "
                   f"{math.nan if cot is None else cot:.2f}")  # fmt: skip
        out.append(f"| {r['row']} | {res} | {r.get('ends', '')} |")
    return "\n".join(out) + "\n"


SUCCESS_GOAL = 0.99
"""The goal of the start, stop, restart and sequence rows: this share of episodes or more."""
TRACK_GOAL_M_S = 0.10
"""The goal of each tracking row: a mean |stride speed - command| at most this [m/s], with
every episode running its 30 s."""
DRIFT_GOAL_M_S = 0.05
"""The goal of the stop row's drift (the hold's mean |hip speed|) [m/s]."""


def goals(rows: list[dict]) -> dict[str, bool]:
    """Whether each row of :func:`run_protocol`'s ``rows`` meets its goal, by row name.

    Start, stop, restart and sequences: a success rate of at least :data:`SUCCESS_GOAL` (the
    stop's drift at most :data:`DRIFT_GOAL_M_S` too); tracking: :data:`TRACK_GOAL_M_S`, every
    episode having run 30 s.
    """
    out = {}
    for r in rows:
        if "success" in r:
            ok = r["success"]["rate"] >= SUCCESS_GOAL
            if "drift_m_s_mean" in r:
                ok = ok and r["drift_m_s_mean"] <= DRIFT_GOAL_M_S
        else:
            err = r["mean_abs_error_m_s"]
            ok = r["ran_30s"] == r["episodes"] and math.isfinite(err) and err <= TRACK_GOAL_M_S
        out[r["row"]] = bool(ok)
    return out


def selection_score(rows: list[dict]) -> float:
    """A run's score of the protocol's ``rows`` (``select_by = "protocol"``): higher is better.

    The number of goals met (:func:`goals`), plus, within [0, 1): half the mean success rate
    of the rows that have one and half of 1 - the worst tracking error over 1 m/s (an
    unmeasured row's error counts as 1 m/s), so that two networks meeting as many goals rank
    by how close they come to the rest.
    """
    rates = [r["success"]["rate"] for r in rows if "success" in r]
    errs = [r["mean_abs_error_m_s"] for r in rows if "success" not in r]
    worst = max((e if math.isfinite(e) else 1.0 for e in errs), default=0.0)
    return (sum(goals(rows).values()) + 0.5 * float(np.mean(rates or [0.0]))
            + 0.5 * (1.0 - min(worst, 1.0)) * 0.999)  # fmt: skip
