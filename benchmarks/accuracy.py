"""Speed against accuracy: work-precision charts, a stability map, MuJoCo validation.

    python -m benchmarks.accuracy [--quick] [--out DIR]

Writes into runs/accuracy (or ``--out``; ``--out benchmarks/results`` updates the committed
ones): work_precision_a.png, work_precision_b.png, stability_map.png, accuracy_tables.md and
accuracy.json, and prints the tables.

Scene (a): model 1 alone (stance foot flat), Table 2's model-1 torques, 1 s from the nominal
posture at rest, integrated without guards. Reference: RK4 at h = 0.01 ms.
Scene (b): the hybrid simulator through model 2 -> 3 -> 4 (heel strike with impact, foot flat
with impact and chain renumbering) from a hand-built model-2 state, zero torque, 0.3 s.
A strict walking step has not been found yet (docs/table2.md), so this partial
cycle is the cleanest two-impact scene. Scene (c): the optimised open-loop table
(training/configs/open_loop_optimised.toml), a complete cycle 1 -> 2 -> 3 -> 4 -> 1 (and the next
1 -> 2) in 2.04 s. Reference (b, c): RK4 with 400 substeps per 20 ms, located events.
Scenes (b) and (c) also sweep the error-controlled RK4_LIMEX's tolerance (ADAPTIVE_TOLS).
Errors are measured on the absolute angles of the six physical links (invariant to the
renumbering), on the switch times, and on the point-contact residual.
Cost: wall time per simulated second (best of 3, compiled loop) and constrained-dynamics
evaluations per simulated second (counted in the solver).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from numba import njit

from biped_constraint_env import dynamics as dyn
from biped_constraint_env.advance import nb_advance_w
from biped_constraint_env.hybrid import W_CNT, nb_make_work
from biped_constraint_env.integrators import STABILITY_CONSTANT, Integrator
from biped_constraint_env.kinematics import K_OZ, K_SIN, NK, nb_fk
from biped_constraint_env.model import paper_biped
from biped_constraint_env.simulator import DEFAULT_OPTIONS, SimOptions
from biped_constraint_env.state import MAX_EVENTS, N_FST
from biped_constraint_env.stepper import S_Q1, S_QD1, nb_integrate_w, nb_make_scratch
from training.plumbing.common import CliParser, command
from training.plumbing.outputs import command_output, save_figure, write_file

RESULTS = Path(__file__).parent / "results"
HYBRID_COLS = [
    "method",
    "locate_events",
    "jdot",
    "h_ms",
    "step_tol",
    "max_angle_err_rad",
    "switch_time_err_s",
    "contact_residual_m",
    "us_per_sim_s",
    "evals_per_sim_s",
]
POSTURE = np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])
TABLE2_ROW1 = np.array([10.0, 120.0, 35.0, 80.0, 0.0])
SUBSTEPS = (1, 2, 4, 8, 16, 32, 64, 128, 256, 400)  # per 20 ms: h = 20 ms ... 0.05 ms
METHODS = ("euler", "semi_implicit", "rk2", "rk4", "limex", "rk4_limex")
"""The fixed-step methods (every scene, the stability map)."""
ADAPTIVE = "rk4_limex_adaptive"
ADAPTIVE_TOLS = (1e-2, 3e-3, 1e-3, 3e-4, 2e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)
"""Error tolerances of the error-controlled method in the hybrid scenes (b, c), at a longest
step of 20 ms (1 per 20 ms, the default; beyond RK4's stability limit) and of 10 ms (2 per
20 ms); the default tolerance is 2e-4. Scene (a) and the stability map run fixed steps
without the hybrid loop, where there is no error control: there it is RK4_LIMEX."""
DIVERGED_RAD_S = 1e3


@njit(cache=True)
def integrate_free(ch, sc, mode, q0, qd0, tau6, h, n, every, iopt, fopt, a, b):
    """n guard-free steps of h in ``mode``; q sampled every ``every`` steps; returns (Q, evals)."""
    W = nb_make_work()
    S = nb_make_scratch()
    q = q0.copy()
    qd = qd0.copy()
    out = np.full((n // every + 1, 6), np.nan)
    out[0] = q
    for k in range(1, n + 1):
        nb_integrate_w(ch, sc, mode, q, qd, tau6, h, iopt, fopt, a, b, W, S, False)
        q[:] = S[S_Q1]
        qd[:] = S[S_QD1]
        if not (np.all(np.isfinite(qd)) and np.abs(qd).max() < 1e3):
            break
        if k % every == 0:
            out[k // every] = q
    return out, W[W_CNT][0]


@njit(cache=True)
def run_hybrid(chs, scs, q0, qd0, mode0, dt, n, iopt, fopt, a, b, tau):
    """n control periods of the hybrid simulator under the per-model torque table ``tau``
    (4, 5); returns link angles, events, residual, evals."""
    W = nb_make_work()
    S = nb_make_scratch()
    q = q0.copy()
    qd = qd0.copy()
    ist = np.array([mode0, 0, 0, 0])
    fst = np.zeros(N_FST)
    ev = np.zeros((MAX_EVENTS, 5))
    forces = np.zeros(5)
    phys = np.full((n + 1, 6), np.nan)
    events = np.zeros((64, 4))
    ne_tot = 0
    resid = 0.0
    K = np.empty((6, NK))
    z6 = np.zeros(6)
    for k in range(n + 1):
        # absolute angles of the physical links (leg A foot, shank, thigh, leg B thigh, shank, foot)
        ang = np.cumsum(chs[ist[1]][:, 4] + q)
        for j in range(6):
            if ist[1] == 0:
                phys[k, j] = ang[j]
            else:
                phys[k, 5 - j] = ang[j] + (0.0 if (j == 0 or j == 5) else np.pi)
        if ist[0] >= 3:
            nb_fk(chs[ist[1]], q, z6, z6, 0.0, K)
            off = scs[ist[1]][4] if ist[0] == 3 else scs[ist[1]][5]
            resid = max(resid, abs(K[5, K_OZ] + off * K[5, K_SIN]))
        if k == n:
            break
        st, ne = nb_advance_w(
            chs, scs, q, qd, ist, fst, tau, dt, iopt, fopt, a, b, ev, forces, W, S
        )
        for e in range(ne):
            if ne_tot < 64:
                events[ne_tot] = ev[e, :4]
                ne_tot += 1
        if st != 0:
            break
    return phys, events[:ne_tot], resid, W[W_CNT][0]


def _wrap(x):
    return np.angle(np.exp(1j * x))


def best_time(fn, repeats=3):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def scene_a(params, quick):
    ch = params.chain(0)
    tau6 = np.concatenate([[0.0], TABLE2_ROW1])
    T = 1.0
    ref_opts = SimOptions(integrator="rk4")
    iopt, fopt, a, b = ref_opts.packed
    h_ref = 1e-5
    n_ref = int(round(T / h_ref))
    every_ref = int(round(0.02 / h_ref))
    ref, _ = integrate_free(
        ch.packed,
        ch.packed_scalars,
        1,
        POSTURE,
        np.zeros(6),
        tau6,
        h_ref,
        n_ref,
        every_ref,
        iopt,
        fopt,
        a,
        b,
    )
    ref2, _ = integrate_free(
        ch.packed,
        ch.packed_scalars,
        1,
        POSTURE,
        np.zeros(6),
        tau6,
        2 * h_ref,
        n_ref // 2,
        every_ref // 2,
        iopt,
        fopt,
        a,
        b,
    )
    ref_err = float(np.abs(ref2 - ref).max())
    rows = []
    variants = [(m, "crba") for m in METHODS] + [("rk4", "newton_euler_columns")]
    for method, mass in variants:
        opts = SimOptions(integrator=method, mass_matrix=mass)
        iopt, fopt, a, b = opts.packed
        for sub in SUBSTEPS if not quick else SUBSTEPS[:6]:
            h = 0.02 / sub
            n = int(round(T / h))
            args = (
                ch.packed,
                ch.packed_scalars,
                1,
                POSTURE,
                np.zeros(6),
                tau6,
                h,
                n,
                sub,
                iopt,
                fopt,
                a,
                b,
            )
            out, evals = integrate_free(*args)
            stable = bool(np.all(np.isfinite(out)))
            err = float(np.abs(_wrap(out - ref)).max()) if stable else np.inf
            wall = best_time(lambda: integrate_free(*args))  # noqa: B023 (called right here)
            rows.append(
                {
                    "scene": "a",
                    "method": method,
                    "mass_matrix": mass,
                    "h_ms": h * 1e3,
                    "substeps_per_20ms": sub,
                    "stable": stable,
                    "max_angle_err_rad": err,
                    "us_per_sim_s": wall / T * 1e6,
                    "evals_per_sim_s": evals / T,
                }
            )
    return rows, ref_err


def scene_b_start(params):
    """Model 2: stance toe pivot, swing heel 2 cm above the floor ahead, toe up 0.1 rad."""
    from biped_constraint_env.kinematics import keypoints, link_angles

    ch = params.chain(0)
    off = np.array([0.0, np.pi / 2, 0.0, np.pi, 0.0, np.pi / 2])
    phi = np.array([-0.15, np.pi / 2 - 0.5, np.pi / 2 - 0.45, -np.pi / 2 + 0.55, 0.0, 0.1])
    hip = keypoints(ch, _wrap(np.diff(np.concatenate([[0.0], phi])) - off))[4]
    s4 = (0.02 - hip[1] - 1.5 * np.sin(phi[3]) + 0.25 * np.sin(phi[5])) / 1.5
    phi[4] = np.arcsin(s4)
    q = _wrap(np.diff(np.concatenate([[0.0], phi])) - off)
    assert abs(link_angles(q)[5] % (2 * np.pi) - 0.1) < 1e-9
    return q


def scene_hybrid(params, quick, label, q0, tau, T):
    """Work-precision of the hybrid simulator from model ``q0`` (mode 1 or 2 inferred)."""
    chs, scs = params.packed
    mode0, q0 = q0
    n = int(round(T / 0.02))
    ref_opts = SimOptions(integrator="rk4", substeps=400, strict=False)
    phys_ref, ev_ref, res_ref, _ = run_hybrid(
        chs, scs, q0, np.zeros(6), mode0, 0.02, n, *ref_opts.packed, tau
    )
    sw_ref = ev_ref[ev_ref[:, 1] == 0]
    rows = []
    variants = [(method, True, "exact") for method in METHODS]
    variants += [
        ("rk2", False, "exact"),
        ("euler", False, "finite_difference"),
        ("rk2", True, "finite_difference"),
    ]
    settings = [
        (method, locate, jdot, sub, None)
        for method, locate, jdot in variants
        for sub in (SUBSTEPS if not quick else SUBSTEPS[:6])
    ]
    settings += [
        (ADAPTIVE, True, "exact", sub, tol)
        for sub in (2, 1)
        for tol in (ADAPTIVE_TOLS if not quick else quick_tolerances())
    ]
    for method, locate, jdot, sub, tol in settings:
        opts = SimOptions(
            integrator=method, substeps=sub, strict=False, locate_events=locate, jdot=jdot
        )
        if tol is not None:
            opts = opts.replace(step_tol=tol)
        packed = opts.packed
        phys, ev, resid, evals = run_hybrid(chs, scs, q0, np.zeros(6), mode0, 0.02, n, *packed, tau)
        sw = ev[ev[:, 1] == 0]
        same = len(sw) >= len(sw_ref) and np.all(sw[: len(sw_ref), 2:] == sw_ref[:, 2:])
        rows_ref = np.isfinite(phys_ref).all(axis=1)
        ok = bool(same and np.isfinite(phys[rows_ref]).all())
        err = float(np.abs(_wrap(phys[rows_ref] - phys_ref[rows_ref])).max()) if ok else np.inf
        t_err = float(np.abs(sw[: len(sw_ref), 0] - sw_ref[:, 0]).max()) if ok else np.inf
        wall = best_time(
            lambda: run_hybrid(chs, scs, q0, np.zeros(6), mode0, 0.02, n, *packed, tau)
        )
        rows.append(
            {
                "scene": label,
                "method": method,
                "locate_events": locate,
                "jdot": jdot,
                "h_ms": 20.0 / sub,
                "substeps_per_20ms": sub,
                "step_tol": tol,
                "same_switches": ok,
                "max_angle_err_rad": err,
                "switch_time_err_s": t_err,
                "contact_residual_m": float(resid),
                "us_per_sim_s": wall / T * 1e6,
                "evals_per_sim_s": evals / T,
            }
        )
    return rows, [(float(t), int(a), int(b)) for t, _, a, b in sw_ref], float(res_ref)


def quick_tolerances() -> tuple[float, ...]:
    """``--quick``'s subset of ADAPTIVE_TOLS: every third, and always the default's own (so
    that the quick run can still say whether the default meets the rule)."""
    return tuple(sorted(set(ADAPTIVE_TOLS[::3]) | {DEFAULT_OPTIONS.step_tol}, reverse=True))


def scene_b(params, quick):
    return scene_hybrid(params, quick, "b", (2, scene_b_start(params)), np.zeros((4, 5)), 0.3)


def scene_c(params, quick):
    """The optimised open-loop table: a complete cycle 1 -> 2 -> 3 -> 4 -> 1 (then 1 -> 2)."""
    import tomllib

    cfg = tomllib.loads(
        (
            Path(__file__).parents[1] / "training" / "configs" / "open_loop_optimised.toml"
        ).read_text()
    )
    tau = np.array(cfg["torques"]).reshape(4, 5)
    return scene_hybrid(params, quick, "c", (1, np.array(cfg["posture"])), tau, 2.04)


def stability_map(params, quick):
    ch = params.chain(0)
    tau6 = np.concatenate([[0.0], TABLE2_ROW1])
    rng = np.random.default_rng(0)
    postures = [POSTURE] + [
        POSTURE + np.concatenate([[0.0], rng.uniform(-0.4, 0.4, 5)])
        for _ in range(2 if quick else 5)
    ]
    D = dyn.damping_matrix(ch)[1:, 1:]
    out = []
    for p_i, q in enumerate(postures):
        M = dyn.mass_matrix(ch, q)[1:, 1:]
        lam = float(np.linalg.eigvals(np.linalg.solve(M, D)).real.max())
        for method in ("euler", "rk2", "rk4", "semi_implicit", "limex", "rk4_limex"):
            opts = SimOptions(integrator=method, project_constraints=False)
            iopt, fopt, a, b = opts.packed

            def stable(h):
                n = int(round(1.0 / h))
                res, _ = integrate_free(
                    ch.packed, ch.packed_scalars, 1, q, np.zeros(6), tau6, h, n, n, iopt, fopt, a, b
                )
                return bool(np.all(np.isfinite(res)))

            lo, hi = 1e-4, 0.1
            if stable(hi):
                h_max = hi
            else:
                for _ in range(14):
                    mid = np.sqrt(lo * hi)
                    lo, hi = (mid, hi) if stable(mid) else (lo, mid)
                h_max = lo
            theory = STABILITY_CONSTANT[Integrator[method.upper()]] / lam
            out.append(
                {
                    "posture": p_i,
                    "method": method,
                    "lambda_max_per_s": lam,
                    "h_stable_ms": h_max * 1e3,
                    "h_theory_ms": theory * 1e3,
                }
            )
    return out


def mujoco_validation(params):
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return {"skipped": "MuJoCo is not installed: pip install -e '.[bench]'"}
    from benchmarks.mujoco_model import build, mass_matrix, simulate

    ch = params.chain(0)
    model, data = build(ch, 1e-4)
    M_err = float(
        np.abs(mass_matrix(model, data, POSTURE[1:]) - dyn.mass_matrix(ch, POSTURE)[1:, 1:]).max()
    )
    t_mj = best_time(lambda: simulate(model, data, POSTURE[1:], TABLE2_ROW1, 1.0, 100))
    _, q_mj = simulate(model, data, POSTURE[1:], TABLE2_ROW1, 1.0, 100)
    opts = SimOptions(integrator="rk4")
    iopt, fopt, a, b = opts.packed
    tau6 = np.concatenate([[0.0], TABLE2_ROW1])

    def ours():
        return integrate_free(
            ch.packed,
            ch.packed_scalars,
            1,
            POSTURE,
            np.zeros(6),
            tau6,
            1e-4,
            10000,
            100,
            iopt,
            fopt,
            a,
            b,
        )

    q_ours = ours()[0][:, 1:]
    t_ours = best_time(ours)
    return {
        "mass_matrix_max_abs_diff": M_err,
        "trajectory_max_abs_diff_rad": float(np.abs(q_ours - q_mj).max()),
        "integrator": "RK4, h = 0.1 ms, 1 s, Table 2 model-1 torques",
        "mujoco_s_per_sim_s": t_mj,
        "ours_s_per_sim_s": t_ours,
        "mujoco_version": __import__("mujoco").__version__,
    }


def _is_reference(row):
    """The hybrid scenes' reference setting itself (its error against itself is 0)."""
    return (
        row["scene"] in ("b", "c")
        and row["method"] == "rk4"
        and row["substeps_per_20ms"] == 400
        and row["locate_events"]
        and row["jdot"] == "exact"
    )


def _curve(row):
    """One curve of a work-precision chart: a method over its step sizes, or the
    error-controlled method over its tolerances at one longest step."""
    key = tuple(
        v for k, v in row.items() if k in ("method", "mass_matrix", "locate_events", "jdot")
    )
    if row.get("step_tol") is not None:
        key += (f"tolerance sweep, steps <= {row['h_ms']:g} ms",)
    return key


def plot(rows_a, rows_b, rows_c, stab, path_a, path_b, path_c, path_s):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for rows, path, title in (
        (rows_a, path_a, "scene (a): model 1, Table 2 row 1, 1 s"),
        (rows_b, path_b, "scene (b): 2 -> 3 -> 4 with impacts, 0.3 s"),
        (rows_c, path_c, "scene (c): a walking cycle 1 -> 2 -> 3 -> 4 -> 1 -> 2 -> 3, 2.04 s"),
    ):
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
        keys = sorted({_curve(r) for r in rows}, key=str)
        for key in keys:
            sel = [
                r
                for r in rows
                if _curve(r) == key and np.isfinite(r["max_angle_err_rad"]) and not _is_reference(r)
            ]
            if not sel:
                continue
            label = " / ".join(str(k) for k in key)
            for ax, xkey in zip(axes, ("us_per_sim_s", "evals_per_sim_s"), strict=True):
                ax.loglog(
                    [r[xkey] for r in sel],
                    [max(r["max_angle_err_rad"], 1e-16) for r in sel],
                    "o-",
                    ms=3,
                    label=label,
                )
        for ax, xl in zip(
            axes,
            ("wall time per simulated second [us]", "dynamics evaluations per simulated second"),
            strict=True,
        ):
            ax.set_xlabel(xl)
            ax.set_ylabel("max link-angle error [rad]")
            ax.axhline(1e-3, color="k", lw=0.6, ls="--")
            ax.grid(True, which="both", lw=0.3)
        axes[0].set_title(title)
        axes[1].legend(fontsize=7)
        fig.tight_layout()
        save_figure(fig, path, dpi=110)
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for method, marker in (("euler", "o"), ("rk2", "s"), ("rk4", "^"), ("rk4_limex", "v")):
        sel = [s for s in stab if s["method"] == method]
        ax.loglog(
            [s["h_theory_ms"] for s in sel], [s["h_stable_ms"] for s in sel], marker, label=method
        )
    lim = [1, 30]
    ax.plot(lim, lim, "k--", lw=0.7, label="found = theory")
    ax.axhline(20.0, color="tab:red", lw=0.7, label="paper's 20 ms")
    ax.set_xlabel("theory: c / lambda_max(M^-1 D) [ms]")
    ax.set_ylabel("largest stable step found [ms]")
    ax.set_title("stability (semi-implicit, LIMEX: stable at every step tried)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path_s, dpi=110)


RULE_ANGLE_RAD = 1e-3
RULE_SWITCH_TIME_S = 1e-3


RULE_KEY = ("method", "locate_events", "jdot", "substeps_per_20ms", "step_tol")
"""What identifies a setting in the hybrid scenes' rows."""


def default_key() -> tuple:
    """The default physics (:data:`DEFAULT_OPTIONS`) as a :data:`RULE_KEY` of the 20 ms scenes."""
    d = DEFAULT_OPTIONS
    tol = d.step_tol if d.integrator == ADAPTIVE else None
    return (d.integrator, d.locate_events, d.jdot, d.substeps, tol)


def meeting_rule(rows_b, rows_c):
    """The accuracy rule: every setting whose link angles stay within 1e-3 rad and switch times
    within 1 ms of the references in both walking scenes (b) and (c), with its evaluations per
    simulated second (the larger of the two scenes), cheapest first."""
    key = RULE_KEY

    def ok(r):
        return (
            r["max_angle_err_rad"] <= RULE_ANGLE_RAD
            and r["switch_time_err_s"] <= RULE_SWITCH_TIME_S
        )

    c_by = {tuple(r[k] for k in key): r for r in rows_c}
    meeting = []
    for rb in rows_b:
        rc = c_by.get(tuple(rb[k] for k in key))
        if rc is None or _is_reference(rb) or not (ok(rb) and ok(rc)):
            continue
        meeting.append(
            {
                **{k: rb[k] for k in key},
                "h_ms": rb["h_ms"],
                "err_b_rad": rb["max_angle_err_rad"],
                "err_c_rad": rc["max_angle_err_rad"],
                "switch_err_b_s": rb["switch_time_err_s"],
                "switch_err_c_s": rc["switch_time_err_s"],
                "evals_per_sim_s": max(rb["evals_per_sim_s"], rc["evals_per_sim_s"]),
            }
        )
    meeting.sort(key=lambda r: r["evals_per_sim_s"])
    return meeting


def rule_choice(meeting):
    """The cheapest setting of each method among ``meeting`` (:func:`meeting_rule`), cheapest
    first (the first is the rule's choice)."""
    firsts, seen = [], set()
    for r in meeting:
        if (r["method"], r["locate_events"], r["jdot"]) not in seen:
            seen.add((r["method"], r["locate_events"], r["jdot"]))
            firsts.append(r)
    return firsts


def _md(rows, cols):
    head = "| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n"

    def fmt(v):
        if v is None:
            return ""
        return f"{v:.3g}" if isinstance(v, float) else str(v)

    return head + "".join("| " + " | ".join(fmt(r[c]) for c in cols) + " |\n" for r in rows)


@command("accuracy")
def main(argv=None) -> int:
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer step sizes and postures")
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help=f"output folder (default: runs/accuracy, with --quick runs/accuracy_quick; "
        f"{RESULTS} updates the committed results)",
    )
    args = ap.parse_args(argv)
    out = args.out or Path("runs/accuracy_quick" if args.quick else "runs/accuracy")
    with command_output(out, "accuracy") as co:
        _run(args.quick, Path(co.dir().where()))
    print(f"wrote {out}")
    return 0


def _run(quick: bool, out: Path) -> None:
    """The study, its figures and tables written into ``out`` (a staging directory)."""
    params = paper_biped()
    from training.plumbing.common import progress

    results = {}
    for name in progress(["a", "b", "c", "stability", "mujoco"], 5, "accuracy study"):
        if name == "a":
            results["scene_a"], results["scene_a_reference_self_error_rad"] = scene_a(params, quick)
        elif name == "b":
            rows, sw, res = scene_b(params, quick)
            results["scene_b"], results["scene_b_reference_switches"] = rows, sw
            results["scene_b_reference_residual_m"] = res
        elif name == "c":
            rows, sw, res = scene_c(params, quick)
            results["scene_c"], results["scene_c_reference_switches"] = rows, sw
            results["scene_c_reference_residual_m"] = res
        elif name == "stability":
            results["stability"] = stability_map(params, quick)
        else:
            results["mujoco"] = mujoco_validation(params)
    plot(
        results["scene_a"],
        results["scene_b"],
        results["scene_c"],
        results["stability"],
        out / "work_precision_a.png",
        out / "work_precision_b.png",
        out / "work_precision_c.png",
        out / "stability_map.png",
    )
    meeting = meeting_rule(results["scene_b"], results["scene_c"])
    results["rule"] = rule_choice(meeting)
    default = [r for r in meeting if tuple(r[k] for k in RULE_KEY) == default_key()]
    results["default"] = {"setting": dict(zip(RULE_KEY, default_key(), strict=True))}
    results["default"]["meets_rule"] = bool(default)
    if default:
        results["default"].update(default[0])
    write_file(out / "accuracy.json", json.dumps(results, indent=1) + "\n")
    md = (
        "## scene (a)\n"
        + _md(
            results["scene_a"],
            [
                "method",
                "mass_matrix",
                "h_ms",
                "max_angle_err_rad",
                "us_per_sim_s",
                "evals_per_sim_s",
            ],
        )
        + "\n## scene (b)\n"
        + _md(results["scene_b"], HYBRID_COLS)
        + "\n## scene (c)\n"
        + _md(results["scene_c"], HYBRID_COLS)
        + "\n## the accuracy rule: cheapest setting of each method meeting it in (b) and (c)\n"
        + _md(
            results["rule"],
            [
                "method",
                "locate_events",
                "jdot",
                "h_ms",
                "step_tol",
                "err_b_rad",
                "err_c_rad",
                "switch_err_b_s",
                "switch_err_c_s",
                "evals_per_sim_s",
            ],
        )
        + "\n## the default physics (DEFAULT_OPTIONS) in the rule\n"
        + json.dumps(results["default"])
        + "\n"
        + "\n## stability\n"
        + _md(
            results["stability"],
            ["posture", "method", "lambda_max_per_s", "h_stable_ms", "h_theory_ms"],
        )
    )
    write_file(out / "accuracy_tables.md", md)
    print(md)
    print("scene (b) reference switches:", results["scene_b_reference_switches"])
    print("scene (c) reference switches:", results["scene_c_reference_switches"])
    print("reference self-error (a), h vs 2h:", results["scene_a_reference_self_error_rad"])
    print("MuJoCo:", json.dumps(results["mujoco"], indent=1))
    print("the default physics in the rule:", json.dumps(results["default"]))


if __name__ == "__main__":
    raise SystemExit(main())
