"""Can the biped stop from its walk at all? A search for torques that bring a walk to rest.

The command policy walks on at a zero command (its stop row is 0%). This study asks whether
that is the physics or the learning: from states of the policy's own walk (where a zero
command would arrive), CMA-ES (the ``cma`` package) searches torques that bring the biped to
rest and hold it there, judged by the protocol's stop test
(:func:`training.plumbing.command_protocol.stands`: at rest within 3 s, held 5 s), under
the default strict physics. The torques, held over each 20 ms period:

    tau = clip(-KP (q - target(t)) - KD qd + ff(t), -150, 150) N m

``target`` a posture (q1..q5) and ``ff`` a feed-forward torque, each piecewise linear through
``--knots`` knots over ``--span-s`` seconds, the posture held and the feed-forward zero after;
``--shape`` says which are searched (``targets``: the posture's knots; ``ff``: the
feed-forward's about one held posture; ``both``). The search starts from a PD hold of the
start's own posture. Every row of one batched env runs one candidate from the same start
(``reset(options=...)``): a generation is one batched rollout.

    python -m training.evaluation.stop_feasibility policies/ppo_command_50hz --out OUT

writes ``OUT/stop_feasibility.json`` (per start: its command, model and speed, the best cost
per generation, whether the best candidate stood, its speed at every period) and prints a
line per start. The starts are the policy's walk from the rest start at a held command, on
development seeds (700000+), ``--at-s`` seconds in.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from training.plumbing.command_protocol import HOLD_S, STOP_WITHIN_S, stands
from training.plumbing.common import CliParser, command
from training.plumbing.outputs import command_output, write_file

KP, KD = 100.0, 10.0
"""The PD law that holds the standing start in model 4 for 10 s ([N m/rad], [N m s/rad])."""
TORQUE_LIMIT = 150.0
PERIOD_S = 0.02


def walk_states(run: Path, command: float, seeds, at_s: float, env_kwargs: dict | None = None):
    """States of the policy's walk at ``command`` from rest, ``at_s`` seconds in (one per seed)."""
    import gymnasium as gym

    from training.ppo.policy_io import load_policy, policy_actor

    policy, norm, cfg, _ = load_policy(run)
    act = policy_actor(policy, norm, cfg)
    kw = {**cfg.env_kwargs(), **(env_kwargs or {}), "start": "rest"}
    out = []
    for seed in seeds:
        env = gym.make(cfg.env_id, **kw)
        obs, info = env.reset(seed=int(seed), options={"command": command})
        y0, t0 = info["hip_y"], info["t"]
        while info["t"] < at_s - 1e-9:
            y0, t0 = info["hip_y"], info["t"]
            obs, _, te, tr, info = env.step(act(obs))
            if te or tr:
                break
        else:
            st = env.unwrapped.state
            vy = (info["hip_y"] - y0) / (info["t"] - t0)
            out.append({"seed": int(seed), "q": st.q.tolist(), "qd": st.qd.tolist(),
                        "mode": int(st.mode), "stance_side": int(st.stance_side),
                        "root_y": float(st.root_y), "hip_vy": vy,
                        "t": float(info["t"])})  # fmt: skip
        env.close()
    return cfg, out


def _at(knots: np.ndarray, t, span_s: float) -> np.ndarray:
    """(n, 5): piecewise-linear ``knots`` (n, 5, K) at ``t`` (scalar or (n,)), held after."""
    n, _, k = knots.shape
    u = np.minimum(np.broadcast_to(np.asarray(t, dtype=float), (n,)) / span_s, 1.0) * (k - 1)
    j = np.minimum(u.astype(int), k - 2)
    w = (u - j)[:, None]
    rows = np.arange(n)
    return (1 - w) * knots[rows, :, j] + w * knots[rows, :, j + 1]


def rollout(venv, start: dict, target: np.ndarray, ff: np.ndarray, span_s: float,
            horizon_s: float):  # fmt: skip
    """Run one candidate per row from ``start``; (t (T,), v (n, T), alive_to (n,)).

    Time is counted in control periods of ``PERIOD_S`` and the speed is the period's hip
    progress over it: a period cut short at a model switch counts whole (the protocol reads
    the simulated time). At rest no period is cut, so a stand's hold is measured exactly; in
    the steps before it the count runs ahead of the simulated time (so "within 3 s" is judged
    late, if anything).

    ``target``, ``ff``: (n, 5, K) knots over ``span_s`` of the PD posture [rad] and the
    feed-forward torque [N m] (the posture held and the feed-forward zero after ``span_s``).
    """
    n = venv.num_envs
    options = {k: start[k] for k in ("q", "qd", "mode", "stance_side", "root_y")}
    obs, info = venv.reset(seed=0, options={**options, "command": 0.0})
    steps = int(round(horizon_s / PERIOD_S))
    alive = np.ones(n, bool)
    alive_to = np.full(n, horizon_s)
    ts, vs = [], []
    y = np.array(info["hip_y"], dtype=float)
    for k in range(steps):
        t = k * PERIOD_S
        f = _at(ff, t, span_s) if t < span_s else 0.0
        q, qd = obs[:, 1:6], obs[:, 7:12]
        tau = np.clip(-KP * (q - _at(target, t, span_s)) - KD * qd + f, -TORQUE_LIMIT,
                      TORQUE_LIMIT)  # fmt: skip
        obs, _, te, tr, info = venv.step(tau.astype(np.float32))
        ny = np.array(info["hip_y"], dtype=float)
        v = (ny - y) / PERIOD_S
        ended = (te | tr) & alive
        alive_to[ended] = (k + 1) * PERIOD_S
        alive &= ~(te | tr)
        v = np.where(alive | ended, v, np.nan)  # a row that ended has no speed after
        ts.append((k + 1) * PERIOD_S)
        vs.append(v)
        y = ny
    return np.array(ts), np.array(vs).T, alive_to


def cost(v: np.ndarray, alive_to: np.ndarray, horizon_s: float) -> np.ndarray:
    """Lower is better: the time not survived first, then the speed after STOP_WITHIN_S.

    On the periods' nominal times: the speed's mean and its largest period, capped at 1 m/s; a
    period after an end counts 1.
    """
    late = np.arange(1, v.shape[1] + 1) * PERIOD_S > STOP_WITHIN_S
    speed = np.minimum(np.where(np.isnan(v), 1.0, np.abs(v)), 1.0)
    return (10.0 * (1.0 - alive_to / horizon_s) + speed[:, late].mean(axis=1)
            + speed[:, late].max(axis=1) + 0.1 * speed.mean(axis=1))  # fmt: skip


SHAPES = ("ff", "targets", "both")
"""What the search varies: the feed-forward torques (about one held posture, also searched),
the PD posture's knots (no feed-forward), or both."""


def search(venv, start: dict, shape: str, knots: int, span_s: float, generations: int,
           sigma: float, seed: int, horizon_s: float):  # fmt: skip
    """CMA-ES from a PD hold on the start's posture; the best candidate's record."""
    import cma

    n = venv.num_envs
    q0 = np.asarray(start["q"][1:], dtype=float)
    n_target = 5 * knots if shape in ("targets", "both") else 5
    n_ff = 5 * knots if shape in ("ff", "both") else 0
    # scale: 0.3 rad for the posture, 30 N m for the feed-forward
    scale = np.concatenate([np.full(n_target, 0.3), np.full(n_ff, 30.0)])
    es = cma.CMAEvolutionStrategy(np.zeros(n_target + n_ff), sigma,
                                  {"popsize": n, "seed": seed, "verbose": -9})  # fmt: skip
    best, history = (math.inf, None), []
    for _ in range(generations):
        z = np.array(es.ask())
        x = z * scale
        target = np.broadcast_to(q0[None, :, None], (n, 5, knots)) + (
            x[:, :n_target].reshape(n, 5, -1)
        )
        ff = x[:, n_target:].reshape(n, 5, knots) if n_ff else np.zeros((n, 5, knots))
        t, v, alive_to = rollout(venv, start, target, ff, span_s, horizon_s)
        c = cost(v, alive_to, horizon_s)
        es.tell(list(z), c.tolist())
        i = int(np.argmin(c))
        history.append(float(c[i]))
        if c[i] < best[0]:
            ok, drift = stands(t, np.nan_to_num(v[i], nan=1.0), 0.0, float(alive_to[i]))
            trace = np.round(np.nan_to_num(v[i], nan=99.0), 4).tolist()
            best = (float(c[i]), {"target": target[i].tolist(), "ff": ff[i].tolist(),
                                  "alive_to_s": float(alive_to[i]), "stood": bool(ok),
                                  "drift_m_s": drift, "v": trace})  # fmt: skip
        if best[1]["stood"] and len(history) > 20:
            break
    return best[1], history


@command("stop_feasibility")
def main(argv: list[str] | None = None) -> int:
    """Walk the policy, search a stop from each start, write the table into ``--out``."""
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("policy", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--commands", type=float, nargs="+", default=[0.6, 1.0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[700000, 700001, 700002])
    ap.add_argument("--at-s", type=float, default=5.0)
    ap.add_argument("--generations", type=int, default=150)
    ap.add_argument("--popsize", type=int, default=32)
    ap.add_argument("--sigma", type=float, default=0.5)
    ap.add_argument("--shape", choices=SHAPES, default="targets")
    ap.add_argument("--knots", type=int, default=9)
    ap.add_argument("--span-s", type=float, default=2.0)
    ap.add_argument("--margin-s", type=float, default=2.0)
    args = ap.parse_args(argv)
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401

    with command_output(args.out, "stop_feasibility") as co:
        horizon = STOP_WITHIN_S + HOLD_S + args.margin_s
        rows = []
        for c in args.commands:
            cfg, starts = walk_states(args.policy, c, args.seeds, args.at_s)
            kw = {**cfg.env_kwargs(), "termination": {"time_limit_s": None}}
            venv = gym.make_vec(cfg.env_id, num_envs=args.popsize,
                                vectorization_mode="vector_entry_point", **kw)  # fmt: skip
            for k, st in enumerate(starts):
                t0 = time.time()
                best, hist = search(
                    venv,
                    st,
                    args.shape,
                    args.knots,
                    args.span_s,
                    args.generations,
                    args.sigma,
                    k + 1,
                    horizon,
                )
                row = {"command_m_s": c, "seed": st["seed"], "mode": st["mode"],
                       "hip_vy_m_s": st["hip_vy"], "stood": bool(best["stood"]),
                       "drift_m_s": best["drift_m_s"], "alive_to_s": best["alive_to_s"],
                       "generations": len(hist), "best_cost": hist, "best": best,
                       "wall_s": time.time() - t0}  # fmt: skip
                rows.append(row)
                print(f"command {c} seed {st['seed']} model {st['mode']} v {st['hip_vy']:.2f} m/s: "
                      f"stood {best['stood']} drift {best['drift_m_s']:.3f} alive "
                      f"{best['alive_to_s']:.2f} s, {len(hist)} generations, "
                      f"{time.time() - t0:.0f} s", flush=True)  # fmt: skip
            venv.close()
        write_file(Path(co.dir().where()) / "stop_feasibility.json", json.dumps({"rows": rows}))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
