"""Seeded episodes of a controller in the env, and their summary.

Shared by :mod:`training.evaluation.evaluate`, :mod:`training.ppo.train` (periodic evaluations)
and the
imitation pipeline; a controller is any callable obs (24,) -> torques (5,) [N m].
:func:`run_episodes_batched` runs the same episodes all at once in the batched env (the
periodic evaluations that select ``best/``).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence

import numpy as np

from biped_constraint_env.observation import OBS_FORCES
from biped_constraint_env.settings import with_keys
from training.plumbing.stats import format_success, success

ENERGY_KEYS = ("motor_work_pos_j", "motor_work_abs_j", "damping_loss_j")
"""The env's ``info`` sums of the episode's energy (at every physics step)."""


def energy(info, weight_n: float, distance_m: float) -> dict:
    """An episode's energy from its last ``info``: the mechanical cost of transport.

    ``cost_of_transport``: the motors' positive work per weight and distance [1] (summed at
    every physics step); ``cost_of_transport_abs``: their absolute work so; ``damping_share``:
    the joint damping's loss over the positive work (what the model's damping alone costs).
    NaN where the episode did not move forward (or did no work).
    """
    pos, ab, damp = (float(info[k]) for k in ENERGY_KEYS)
    moved = distance_m > 0
    return {
        "work_pos_j": pos,
        "work_abs_j": ab,
        "damping_loss_j": damp,
        "cost_of_transport": pos / (weight_n * distance_m) if moved else math.nan,
        "cost_of_transport_abs": ab / (weight_n * distance_m) if moved else math.nan,
        "damping_share": damp / pos if pos > 0 else math.nan,
    }


COMPARE_PUSH = {"push_impulse_ns": -0.25, "push_at_s": 2.0}
"""The push of ``--compare``: a backward hip impulse of 0.25 N s (about -0.3 m/s), 2 s into
the episode (the env's ``perturbations`` option: through the constrained impulse map)."""


def _time_limit(env_kwargs: dict, episode_s: float | None) -> dict:
    """The env's keyword arguments with the episodes' time limit.

    ``episode_s`` [s]: truncation by simulated time (the env's ``time_limit_s``); None: the
    training recipes' selection episodes, :data:`~biped_constraint_env.tasks.MAX_EPISODE_STEPS`
    control periods (28-30 s at 5 ms, 120 s at 20 ms).
    """
    if episode_s is None:
        from biped_constraint_env.tasks import MAX_EPISODE_STEPS

        return {**with_keys(env_kwargs, "termination", time_limit_s=None),
                "max_episode_steps": MAX_EPISODE_STEPS}  # fmt: skip
    return with_keys(env_kwargs, "termination", time_limit_s=episode_s)


def run_episodes(
    actor: Callable[[np.ndarray], np.ndarray],
    env_kwargs: dict,
    seeds: Sequence[int],
    env_id: str = "ConstrainedBiped-v0",
    record=None,
    desc: str = "",
    episode_s: float | None = None,
) -> list[dict]:
    """Run one episode per seed; per episode: steps, distance, speed, torque cost, end.

    ``record(env, episode_index)`` is called before every step if given (frames for figures).
    Torque cost: the integral of
    sum(tau^2) dt over the episode per metre of hip travel [N^2 m s].
    """
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401
    from training.plumbing.common import progress

    env = gym.make(env_id, **_time_limit(env_kwargs, episode_s),
                   render_mode="rgb_array" if record else None)  # fmt: skip
    params = env.unwrapped.params
    weight = params.total_mass_kg * params.gravity_mps2
    out = []
    for k, seed in enumerate(progress(seeds, len(seeds), desc, enabled=bool(desc))):
        obs, info = env.reset(seed=int(seed))
        if hasattr(actor, "reset"):  # a controller with per-episode memory (a start phase)
            actor.reset()
        y0, t_prev, cost, ret, done = info["hip_y"], 0.0, 0.0, 0.0, False
        steps, step_t, step_hip, step_work, first_m = 0, [], [], [], None
        while not done:
            if record:
                record(env, k)
            tau = actor(obs)
            obs, r, term, trunc, info = env.step(tau)
            applied = info.get("torque", tau)  # PD-target actions: the torques they gave
            cost += float(np.sum(np.square(applied))) * (info["t"] - t_prev)
            t_prev = info["t"]
            ret += r
            done = term or trunc
            if info["steps_completed"] > steps:  # a step completed in this period
                steps = info["steps_completed"]
                step_t.append(info["t"])
                step_hip.append(info["hip_y"] - y0)
                step_work.append(info["motor_work_pos_j"])
                if first_m is None:  # the new stance toe's advance over the start's [m]
                    first_m = float(env.unwrapped.state.root_y)
        dist = info["hip_y"] - y0
        out.append(
            {
                "seed": int(seed),
                "steps_completed": int(info["steps_completed"]),
                "distance_m": dist,
                "speed_m_s": dist / max(info["t"], 1e-9),
                "torque_cost": cost / max(dist, 1e-3) if dist > 0 else float("nan"),
                **energy(info, weight, dist),
                "return": ret,
                "t_s": info["t"],
                "end": info["termination_reason"] or "time_limit",
                "step_t_s": step_t,
                "step_hip_y_m": step_hip,
                "step_work_pos_j": step_work,
                "first_step_m": first_m,
            }
        )
    env.close()
    return out


def run_episodes_batched(
    act: Callable[[np.ndarray], np.ndarray],
    env_kwargs: dict,
    seeds: Sequence[int],
    env_id: str = "ConstrainedBiped-v0",
    num_threads: int = 1,
    episode_s: float | None = None,
    progress: str | None = None,
) -> list[dict]:
    """:func:`run_episodes`' episodes, all at once in the batched vector env.

    ``act(obs (n, d)) -> torques (n, 5)`` [N m] answers every episode's observation in one call
    (one network forward for all of them). Episode i is the single env's episode of
    ``seeds[i]`` (same start, physics, checks and time limit; the batched env steps the same
    compiled simulator), so the per-episode steps, distance, return and end equal
    :func:`run_episodes`' for a controller that gives the same torques batched as alone. It
    costs about one episode's wall time instead of one per seed; it records the steps' times
    and hip positions, the first step's length (not the torque cost), and the energy of
    :func:`energy`.
    """
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401

    venv = gym.make_vec(
        env_id,
        num_envs=len(seeds),
        vectorization_mode="vector_entry_point",
        num_threads=num_threads,
        **_time_limit(env_kwargs, episode_s),
    )
    obs, info = venv.reset(seed=[int(s) for s in seeds])
    y0 = info["hip_y"].copy()
    ret = np.zeros(len(seeds))
    live = np.ones(len(seeds), bool)
    final = {}
    steps = np.zeros(len(seeds), np.int64)
    pushes: list[list[float]] = [[] for _ in seeds]
    step_t: list[list[float]] = [[] for _ in seeds]
    step_hip: list[list[float]] = [[] for _ in seeds]
    step_work: list[list[float]] = [[] for _ in seeds]
    first_m = np.full(len(seeds), math.nan)
    bar = _period_bar(venv, progress)
    while live.any():
        if bar is not None:
            bar.update(1)
        tau = np.asarray(act(obs), dtype=np.float64)
        tau[~live] = 0.0  # finished episodes autoreset on this step; their action is ignored
        obs, r, term, trunc, info = venv.step(tau)
        ret[live] += r[live]
        if "push_dv_m_s" in info:
            for i in np.flatnonzero(live & (info["push_dv_m_s"] != 0.0)):
                pushes[i].append(float(info["push_dv_m_s"][i]))
        for i in np.flatnonzero(live & (info["steps_completed"] > steps)):
            if steps[i] == 0:  # the new stance toe's advance over the start's [m]
                first_m[i] = float(info["root_y"][i])
            steps[i] = info["steps_completed"][i]
            step_t[i].append(float(info["t"][i]))
            step_hip[i].append(float(info["hip_y"][i] - y0[i]))
            step_work[i].append(float(info["motor_work_pos_j"][i]))
        for i in np.flatnonzero(live & (term | trunc)):
            live[i] = False
            final[i] = {k: info[k][i] for k in ("steps_completed", "hip_y", "t") + ENERGY_KEYS}
            final[i]["end"] = info["termination_reason"][i] or "time_limit"
    if bar is not None:
        bar.close()
    params = venv.unwrapped.params
    venv.close()
    weight = params.total_mass_kg * params.gravity_mps2
    return [_batched_episode(int(seed), final[i], float(y0[i]), float(ret[i]), weight,
                             step_t[i], step_hip[i], step_work[i], pushes[i], first_m[i])
            for i, seed in enumerate(seeds)]  # fmt: skip


def _period_bar(venv, desc: str | None):
    """A progress bar over the episodes' control periods (their time limit), or None."""
    u = venv.unwrapped
    total = u.max_episode_steps
    if total is None and u.settings.time_limit_s is not None:  # by time: about this many
        total = math.ceil(u.settings.time_limit_s / u.settings.dt)
    if desc is None or not total:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=desc[:40], unit=" periods", mininterval=1.0, leave=False)


def _batched_episode(seed, f, y0, ret, weight, step_t, step_hip, step_work, pushes,
                     first_m=math.nan) -> dict:  # fmt: skip
    """One episode's record of :func:`run_episodes_batched` (``f``: its last info)."""
    dist = float(f["hip_y"] - y0)
    return {
        "seed": seed,
        "steps_completed": int(f["steps_completed"]),
        "distance_m": dist,
        "speed_m_s": dist / max(float(f["t"]), 1e-9),
        "return": ret,
        "t_s": float(f["t"]),
        "end": f["end"],
        **energy(f, weight, dist),
        "step_t_s": step_t,
        "step_hip_y_m": step_hip,
        "step_work_pos_j": step_work,
        "first_step_m": None if math.isnan(first_m) else float(first_m),
        "push_dv_m_s": pushes,  # the hip's velocity change of each push
    }


STEADY_FROM_STEP = 10
"""Steps from this one on set an episode's steady speed (for the initiation figures)."""


def initiation(eps: list[dict], min_steps: int = 1) -> dict:
    """Gait-initiation figures of episodes started at rest.

    Success: at least ``min_steps`` completed steps. Over the episodes that completed a first
    step: the time to it [s] and its length (the new stance toe's advance) [m]; over those
    with at least ``STEADY_FROM_STEP`` + 2 steps: the steps until the hip's speed over one step
    first reaches 90 % of the steady speed (the median of the per-step speeds from step
    ``STEADY_FROM_STEP`` on).
    """
    first = [e for e in eps if e["step_t_s"]]
    to_90 = []
    for e in eps:
        t = np.array([0.0, *e["step_t_s"]])
        y = np.array([0.0, *e["step_hip_y_m"]])
        if len(t) < STEADY_FROM_STEP + 3:
            continue
        v = np.diff(y) / np.diff(t)  # speed over each step
        steady = float(np.median(v[STEADY_FROM_STEP:]))
        to_90.append(int(np.argmax(v >= 0.9 * steady)) + 1)
    ok = [e for e in eps if e["steps_completed"] >= min_steps]
    return {
        "episodes": len(eps),
        "success_rate": len(ok) / len(eps),
        "success_min_steps": min_steps,
        "t_first_step_s_mean": _mean([e["step_t_s"][0] for e in first]),
        "t_first_step_s_max": max((e["step_t_s"][0] for e in first), default=float("nan")),
        "first_step_m_mean": _mean([e["first_step_m"] for e in first]),
        "steps_to_90pct_speed_mean": _mean(to_90),
        "steps_to_90pct_speed_max": max(to_90, default=float("nan")),
    }


def _nanmean(x) -> float:
    return float(np.nanmean(x)) if np.isfinite(x).any() else math.nan


def _mean(x) -> float:
    return float(np.mean(x)) if len(x) else float("nan")


def summarize(label: str, eps: list[dict]) -> dict:
    """Mean/std/min of steps, distance and speed, mean torque cost, and the ends."""
    s = np.array([e["steps_completed"] for e in eps], dtype=float)
    d = np.array([e["distance_m"] for e in eps])
    v = np.array([e["speed_m_s"] for e in eps])
    c = np.array([e.get("torque_cost", math.nan) for e in eps])
    cot = np.array([e.get("cost_of_transport", math.nan) for e in eps])
    cot_abs = np.array([e.get("cost_of_transport_abs", math.nan) for e in eps])
    share = np.array([e.get("damping_share", math.nan) for e in eps])
    return {
        "controller": label,
        "episodes": eps,
        "steps_mean": s.mean(),
        "steps_std": s.std(),
        "steps_min": int(s.min()),
        "distance_mean_m": d.mean(),
        "distance_std_m": d.std(),
        "speed_mean_m_s": v.mean(),
        "torque_cost_mean": float(np.nanmean(c)) if np.isfinite(c).any() else float("nan"),
        "cost_of_transport_mean": _nanmean(cot),
        "cost_of_transport_abs_mean": _nanmean(cot_abs),
        "damping_share_mean": _nanmean(share),
        "success": success([e["steps_completed"] for e in eps]),
        "ends": dict(Counter(e["end"] for e in eps)),
    }


TABLE_HEADER = (
    "| controller | success (>= 20 steps in 30 s), 95% CI | complete steps (mean ± std, min) | "
    "distance [m] | speed [m/s] | cost of transport | ends |\n|---|---|---|---|---|---|---|"
)
"""The header of :func:`table_row`'s rows."""


def table_row(r: dict) -> str:
    """One markdown row of a :func:`summarize` result (columns of :data:`TABLE_HEADER`)."""
    return (
        f"| {r['controller']} | {format_success(r['success'])} | {r['steps_mean']:.1f} ± "
        f"{r['steps_std']:.1f}, min {r['steps_min']} | {r['distance_mean_m']:.2f} ± "
        f"{r['distance_std_m']:.2f} | {r['speed_mean_m_s']:.2f} | "
        f"{r['cost_of_transport_mean']:.2f} | {r['ends']} |"
    )


def com_and_cop(env) -> tuple[np.ndarray, float]:
    """The centre of mass (y, z) [m] and the centre of pressure y [m] of an env's state.

    The centre of pressure is the force-weighted mean of the contact points' y: the stance
    toe and heel (their normal forces, observation entries 21-22) and the point contact (23:
    the swing heel in model 3, the trailing toe in model 4).
    """
    u = env.unwrapped
    st = u.state
    pts = u.keypoints()
    links = u.params.chain(st.stance_side).links
    segments = (
        ("stance_heel", "stance_toe"),
        ("stance_ankle", "stance_knee"),
        ("stance_knee", "hip"),
        ("hip", "swing_knee"),
        ("swing_knee", "swing_ankle"),
        ("swing_heel", "swing_toe"),
    )
    m = np.array([link.mass_kg for link in links])
    mid = np.array([(pts[a] + pts[b]) / 2 for a, b in segments])
    com = (m[:, None] * mid).sum(axis=0) / m.sum()
    point = "swing_heel" if int(st.mode) == 3 else "swing_toe"
    f = u.core.buf.obs[0, OBS_FORCES]
    y = np.array([pts["stance_toe"][0], pts["stance_heel"][0], pts[point][0]])
    cop = float((f * y).sum() / f.sum()) if f.sum() > 1e-9 else float("nan")
    return com, cop


def batched_row(
    label: str, act, env_kw: dict, seeds, env_id: str, rest: bool = False, progress: str = ""
) -> dict:
    """A row of ``seeds`` report episodes (30 s) run at once in the batched env, printed.

    ``rest``: with the gait-initiation summary (:func:`initiation`). ``progress``: the
    progress bar's label (default: ``label``).
    """
    import time

    from biped_constraint_env.tasks import EPISODE_S
    from training.plumbing.stats import MIN_STEPS

    t0 = time.time()
    eps = run_episodes_batched(act, env_kw, seeds, env_id, episode_s=EPISODE_S,
                               progress=progress or label)  # fmt: skip
    row = summarize(label, eps)
    if rest:
        row["initiation"] = initiation(row["episodes"], MIN_STEPS)
    print(f"{table_row(row)} ({time.time() - t0:.0f} s)", flush=True)
    return row
