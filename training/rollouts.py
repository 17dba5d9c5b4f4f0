"""Seeded episodes of a controller in the env, their summary, and the push perturbation.

Shared by :mod:`training.evaluate`, :mod:`training.train_ppo` (periodic evaluations) and the
imitation pipeline; a controller is any callable obs (24,) -> torques (5,) [N m].
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence

import numpy as np

PUSH_HIP_DV_M_S = (-0.3, 0.0)
"""The push of ``--compare``: a sudden change of the hip's velocity (y, z) [m/s] (backward),
applied once, 2 s into the episode, through the constraint-consistent joint rates."""
PUSH_TIME_S = 2.0


def push(env, dv=PUSH_HIP_DV_M_S) -> None:
    """Change the hip's velocity by ``dv`` (y, z) [m/s] at once, keeping the model's contacts.

    The joint rates change by the least-norm solution of J_hip dqd = dv among the rates that
    keep the current model's contacts (theta0 frozen in models 1 and 4, the point contact of
    models 3 and 4 at rest); the state is set in the simulator directly.
    """
    from biped_constraint_env.kinematics import nb_point_jacobian
    from biped_constraint_env.model import SC_HEEL5, SC_TOE5

    u = env.unwrapped
    st = u.state
    ch = u.params.chain(st.stance_side)
    J_hip = nb_point_jacobian(ch.packed, st.q, 3, 0.0)
    rows = [J_hip[0], J_hip[1]]
    rhs = [dv[0], dv[1]]
    mode = int(st.mode)
    if mode in (1, 4):
        e = np.zeros(6)
        e[0] = 1.0
        rows.append(e)
        rhs.append(0.0)
    if mode in (3, 4):  # the swing foot's heel (3) or toe (4) stays on the ground
        s = float(ch.packed_scalars[SC_HEEL5 if mode == 3 else SC_TOE5])
        J = nb_point_jacobian(ch.packed, st.q, 5, s)
        rows += [J[0], J[1]]
        rhs += [0.0, 0.0]
    A = np.array(rows)
    dq = np.linalg.lstsq(A, np.array(rhs), rcond=None)[0]
    u._sim.qd[0] = st.qd + dq


def run_episodes(
    actor: Callable[[np.ndarray], np.ndarray],
    env_kwargs: dict,
    seeds: Sequence[int],
    env_id: str = "ConstrainedBiped-v0",
    record=None,
    push_at_s: float | None = None,
    desc: str = "",
) -> list[dict]:
    """Run one episode per seed; per episode: steps, distance, speed, torque cost, end.

    ``record(env, episode_index)`` is called before every step if given (frames for figures).
    ``push_at_s``: apply :func:`push` once at that time [s]. Torque cost: the integral of
    sum(tau^2) dt over the episode per metre of hip travel [N^2 m s].
    """
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401
    from training.common import progress

    env = gym.make(env_id, **env_kwargs, render_mode="rgb_array" if record else None)
    out = []
    for k, seed in enumerate(progress(seeds, len(seeds), desc, enabled=bool(desc))):
        obs, info = env.reset(seed=int(seed))
        y0, t_prev, cost, ret, done, pushed = info["hip_y"], 0.0, 0.0, 0.0, False, False
        while not done:
            if record:
                record(env, k)
            if push_at_s is not None and not pushed and info["t"] >= push_at_s:
                push(env)
                pushed = True
            tau = actor(obs)
            obs, r, term, trunc, info = env.step(tau)
            cost += float(np.sum(np.square(tau))) * (info["t"] - t_prev)
            t_prev = info["t"]
            ret += r
            done = term or trunc
        dist = info["hip_y"] - y0
        out.append(
            {
                "seed": int(seed),
                "steps_completed": int(info["steps_completed"]),
                "distance_m": dist,
                "speed_m_s": dist / max(info["t"], 1e-9),
                "torque_cost": cost / max(dist, 1e-3) if dist > 0 else float("nan"),
                "return": ret,
                "t_s": info["t"],
                "end": info["termination_reason"] or "time_limit",
            }
        )
    env.close()
    return out


def summarize(label: str, eps: list[dict]) -> dict:
    """Mean/std/min of steps, distance and speed, mean torque cost, and the ends."""
    s = np.array([e["steps_completed"] for e in eps], dtype=float)
    d = np.array([e["distance_m"] for e in eps])
    v = np.array([e["speed_m_s"] for e in eps])
    c = np.array([e["torque_cost"] for e in eps])
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
        "ends": dict(Counter(e["end"] for e in eps)),
    }


def table_row(r: dict) -> str:
    """One markdown row of a :func:`summarize` result."""
    return (
        f"| {r['controller']} | {r['steps_mean']:.1f} ± {r['steps_std']:.1f}, min {r['steps_min']}"
        f" | {r['distance_mean_m']:.2f} ± {r['distance_std_m']:.2f} | {r['speed_mean_m_s']:.2f} "
        f"| {r['torque_cost_mean']:.0f} | {r['ends']} |"
    )
