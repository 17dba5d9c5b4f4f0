"""Speed of the simulator core, side by side with Pinocchio, in one run.

    python -m benchmarks.bench_core

Prints: us per constrained dynamics evaluation (model 2: 6 unknowns; model 3: 6 + f_n), for
this project (compiled core called from Python, and inside a compiled loop) and for
Pinocchio (``aba`` for model 2; the KKT ``forwardDynamics`` with the same 1x6 constraint
Jacobian and drift for model 3); and us per 20 ms control step at the default settings.
Also checks M and the bias against Pinocchio (printed, not asserted).
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from biped_constraint_env import dynamics as dyn
from biped_constraint_env.advance import nb_advance, nb_advance_batch
from biped_constraint_env.hybrid import nb_make_work, nb_solve_mode, nb_solve_mode_w
from biped_constraint_env.kinematics import point_bias_acceleration, point_jacobian
from biped_constraint_env.model import paper_biped
from biped_constraint_env.simulator import DEFAULT_OPTIONS, FAST_OPTIONS, SimState, step
from biped_constraint_env.state import MAX_EVENTS, N_FST
from training.plumbing.common import CliParser, command, int_in


def _timeit(fn, n: int, repeats: int = 5) -> float:
    """Best of ``repeats`` mean times per call [us]."""
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


@njit(cache=True)
def _solve_loop(ch, sc, mode, q, qd, tau6, n):
    W = nb_make_work()
    acc = 0.0
    for _ in range(n):
        acc += nb_solve_mode_w(ch, sc, mode, q, qd, tau6, 0.0, 0.0, 1e-3, W)[0]
    return acc


@command("bench_core")
def main(argv=None) -> int:
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int_in(1, 10_000_000), default=20000, help="calls per timing")
    args = ap.parse_args(argv)
    params = paper_biped()
    chain = params.chain(0)
    ch, sc = chain.packed, chain.packed_scalars
    rng = np.random.default_rng(0)
    q = np.array([-0.15, -0.35, 0.05, 1.0, -0.14, -0.21])
    qd = rng.normal(size=6)
    tau6 = np.array([0.0, 40.0, 0.0, 30.0, -30.0, -5.0])
    D = dyn.damping_matrix(chain)
    heel = float(sc[4])

    rows = []
    for mode in (2, 3):
        nb_solve_mode(ch, sc, mode, q, qd, tau6, 0.0, 0.0, 1e-3)
        t_py = _timeit(lambda: nb_solve_mode(ch, sc, mode, q, qd, tau6, 0.0, 0.0, 1e-3), args.n)
        _solve_loop(ch, sc, mode, q, qd, tau6, 10)
        t0 = time.perf_counter()
        _solve_loop(ch, sc, mode, q, qd, tau6, args.n * 10)
        t_loop = (time.perf_counter() - t0) / (args.n * 10) * 1e6
        rows.append((mode, t_py, t_loop))

    try:
        import pinocchio as pin

        from benchmarks.pin_model import build

        model, data = build(chain)
        tau_eff = tau6 - D @ qd
        t_aba = _timeit(lambda: pin.aba(model, data, q, qd, tau_eff), args.n)
        J = point_jacobian(chain, q, 5, heel)[1:2].copy()
        gamma = point_bias_acceleration(chain, q, qd, 5, heel)[
            1:2
        ].copy()  # Pinocchio: J a + gamma = 0
        t_kkt = _timeit(
            lambda: pin.forwardDynamics(model, data, q, qd, tau_eff, J, gamma, 0.0), args.n
        )
        qdd_pin = pin.forwardDynamics(model, data, q, qd, tau_eff, J, gamma, 0.0).copy()
        M_pin = pin.crba(model, data, q)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        b_pin = pin.rnea(model, data, q, qd, np.zeros(6))
        M_err = np.abs(M_pin - dyn.mass_matrix(chain, q)).max() / np.abs(M_pin).max()
        b_ours = dyn.bias_forces(chain, q, qd)
        b_err = np.abs(b_pin - b_ours).max() / np.abs(b_pin).max()
        pin_rows = {2: t_aba, 3: t_kkt}
        print(f"Pinocchio {pin.__version__}: M rel. diff {M_err:.1e}, bias rel. diff {b_err:.1e}")
        print(
            "  (model 3 with K = 0 to match Pinocchio's frictionless KKT: "
            f"max |qdd diff| = {np.abs(qdd_pin - _frictionless(params, q, qd, tau6)).max():.1e})"
        )
    except ImportError:
        pin_rows = {}
        print("pinocchio not installed (pip install pin): Pinocchio columns skipped")

    print(f"\n{'evaluation':<34}{'ours, from Python':>19}{'ours, in a loop':>17}{'Pinocchio':>12}")
    for mode, t_py, t_loop in rows:
        label = {2: "model 2 (6 unknowns, aba)", 3: "model 3 (6 + f_n, KKT)"}[mode]
        pin_t = f"{pin_rows[mode]:.2f} us" if mode in pin_rows else "n/a"
        print(f"{label:<34}{t_py:>16.2f} us{t_loop:>14.2f} us{pin_t:>12}")

    # one default 20 ms control step, compiled call: (a) model 1 at rest, no event;
    # (b) Table 2's model-1 torques from the same posture (events located inside the step)
    chs, scs = params.packed
    q0 = np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])
    ev = np.zeros((MAX_EVENTS, 5))
    forces = np.zeros(5)
    print()
    t_eval = rows[0][2]  # model 2, in a loop: the unit of the evaluation-equivalents
    for opts in (DEFAULT_OPTIONS.replace(strict=False), FAST_OPTIONS.replace(strict=False)):
        _control_steps(params, opts, chs, scs, q0, ev, forces, args, 0.02, t_eval)
    # the env's default control period (the walking task) with the env's own options
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401  (registers the id)

    env = gym.make("ConstrainedBiped-v0").unwrapped
    opts = env.options.replace(strict=False, stop_at_switch=False)
    _control_steps(params, opts, chs, scs, q0, ev, forces, args, env.dt, t_eval)
    return 0


def _control_steps(params, opts, chs, scs, q0, ev, forces, args, dt, t_eval):
    iopt, fopt, a, b = opts.packed
    state0 = SimState(0.0, 1, 0, q0, np.zeros(6))
    for label, torque in (
        ("no event", np.zeros(5)),
        ("Table 2 row 1, events", np.array([10.0, 120.0, 35.0, 80.0, 0.0])),
    ):
        table = np.tile(torque, (4, 1))
        qq, vv = q0.copy(), np.zeros(6)
        ist, fst = np.array([1, 0, 0, 0], np.int64), np.zeros(N_FST)

        def compiled():
            qq[:] = q0
            vv[:] = 0.0
            ist[:] = (1, 0, 0, 0)
            fst[:] = 0.0
            nb_advance(chs, scs, qq, vv, ist, fst, table, dt, iopt, fopt, a, b, ev, forces)

        compiled()
        t_c = _timeit(compiled, max(args.n // 10, 100))
        t_api = _timeit(lambda: step(params, state0, table, dt, opts), max(args.n // 20, 100))
        n_b = 256
        Q = np.tile(q0, (n_b, 1))
        QD = np.zeros((n_b, 6))
        IST = np.tile(np.array([1, 0, 0, 0], np.int64), (n_b, 1))
        FST = np.zeros((n_b, N_FST))
        TAU = np.tile(table, (n_b, 1, 1))
        EV = np.zeros((n_b, MAX_EVENTS, 5))
        FO = np.zeros((n_b, 5))
        STATUS = np.zeros(n_b, np.int64)
        NEV = np.zeros(n_b, np.int64)

        def batch():
            Q[:] = q0
            QD[:] = 0.0
            IST[:] = (1, 0, 0, 0)
            FST[:] = 0.0
            STATUS[:] = 0
            nb_advance_batch(
                chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FO, STATUS, NEV
            )

        batch()
        t_b = _timeit(batch, 20) / n_b
        print(
            f"{dt * 1e3:g} ms control step ({opts.integrator} x {opts.substeps}, {label}): "
            f"simulator.step {t_api:.1f} us | compiled call {t_c:.1f} us | "
            f"batched, per simulator {t_b:.1f} us = {t_b / t_eval:.1f} evaluation-equivalents"
        )
    return 0


def _frictionless(params, q, qd, tau6):
    import dataclasses

    p = dataclasses.replace(params, friction_ratio=0.0)
    c = p.chain(0)
    return nb_solve_mode(c.packed, c.packed_scalars, 3, q, qd, tau6, 0.0, 0.0, 1e-3)[0]


if __name__ == "__main__":
    raise SystemExit(main())
