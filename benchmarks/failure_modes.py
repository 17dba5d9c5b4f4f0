"""Where methods fail beyond the step size (figures into runs/failure_modes, or --out).

    python -m benchmarks.failure_modes

1. Conditioning of the constrained solve. With the contact Jacobian row J_c and the friction
   row J_f = J_c - K s J_t, the KKT matrix is singular exactly when the scalar Schur complement
   J_c M^-1 J_f^T vanishes. Without friction it is J_c M^-1 J_c^T > 0 (regular as long as the
   contact point can move vertically at all); with sliding friction it falls as K grows and
   crosses zero at K* = J_c M^-1 J_c^T / (s J_c M^-1 J_t^T) (a Painleve-type inconsistency:
   beyond it the normal force needed to hold the contact changes sign). The script sweeps K for
   a sliding model-3 state and the stance knee towards straight, printing the Schur complement
   and our LU pivot ratio (reported by the solver) -> conditioning.png.
2. Friction direction at zero slip: the paper's v/|v| is discontinuous; we use
   v/sqrt(v^2 + eps^2). Its slope K f_n / eps makes the contact stiff near zero slip, which is
   what limits every explicit method's convergence in the accuracy study -> friction_law.png.
3. Grazing impacts: a heel arriving with vertical speed -> 0. Event location still brackets the
   touchdown (guard root) and the plastic impulse -> 0 continuously; printed.
4. Chattering (Zeno): more than ``max_switches`` model switches in one control period end the
   run with the named event ``zeno`` instead of looping (tests/test_simulator.py::test_event_zeno).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from biped_constraint_env import dynamics as dyn
from biped_constraint_env import kinematics as kin
from biped_constraint_env.hybrid import nb_impact, nb_solve_mode
from biped_constraint_env.model import paper_biped
from training.plumbing.common import CliParser, command
from training.plumbing.outputs import command_output, save_figure, write_file

RESULTS = Path(__file__).parent / "results"
HEEL = -0.25  # swing heel offset from the swing ankle [m]


def model3_q(theta0=-0.15, stance_knee=0.05, phi5=0.2):
    """A model-3 posture (swing heel on the floor ahead), as in the tests."""
    ch = paper_biped().chain(0)
    off = np.array([0.0, np.pi / 2, 0.0, np.pi, 0.0, np.pi / 2])
    phi = np.array(
        [theta0, np.pi / 2 - 0.5, np.pi / 2 - 0.5 + stance_knee, -np.pi / 2 + 0.55, 0.0, phi5]
    )

    def q_of(p):
        return np.angle(np.exp(1j * (np.diff(np.concatenate([[0.0], p])) - off)))

    hip = kin.keypoints(ch, q_of(phi))[4]
    s4 = (-hip[1] - 1.5 * np.sin(phi[3]) - HEEL * np.sin(phi5)) / 1.5
    phi[4] = np.arcsin(np.clip(s4, -1, 1))
    return q_of(phi)


def _contact_terms(params, q, qd):
    """(M, heel Jacobian J (2, 6), regularised slip sign s) of the model-3 heel contact."""
    ch = params.chain(0)
    M = dyn.mass_matrix(ch, q)
    J = kin.point_jacobian(ch, q, 5, HEEL)
    v = J[0] @ qd
    return M, J, v / np.sqrt(v * v + 1e-6)


def schur(params, q, qd):
    """(J_c M^-1 J_f^T, J_c M^-1 J_c^T, s J_c M^-1 J_t^T) of the model-3 heel contact."""
    M, J, s = _contact_terms(params, q, qd)
    jf = J[1] - params.friction_ratio * s * J[0]
    return (
        float(J[1] @ np.linalg.solve(M, jf)),
        float(J[1] @ np.linalg.solve(M, J[1])),
        float(s * J[1] @ np.linalg.solve(M, J[0])),
    )


def inv_cond_kkt(params, q, qd):
    """1 / cond of the model-3 KKT matrix [[M, -J_f^T], [J_c, 0]] (numpy, for the figure)."""
    M, J, s = _contact_terms(params, q, qd)
    A = np.zeros((7, 7))
    A[:6, :6] = M
    A[:6, 6] = -(J[1] - params.friction_ratio * s * J[0])
    A[6, :6] = J[1]
    return 1.0 / np.linalg.cond(A)


def conditioning():
    base = paper_biped()
    q = model3_q()
    qd = np.zeros(6)
    ch = base.chain(0)
    J = kin.point_jacobian(ch, q, 5, HEEL)
    qd = 2.0 * np.linalg.pinv(J[:1]) @ np.array([1.0])  # the heel sliding forward at 2 m/s
    _, a, b = schur(base, q, qd)
    k_star = a / b if b > 0 else np.inf
    ks = np.linspace(0.0, 2 * max(k_star, 1.0) if np.isfinite(k_star) else 3.0, 200)
    rows = []
    for K in ks:
        p = dataclasses.replace(base, friction_ratio=float(K))
        sc, _, _ = schur(p, q, qd)
        c = p.chain(0)
        _, fn, _, _ = nb_solve_mode(
            c.packed, c.packed_scalars, 3, q, qd, np.zeros(6), 0.0, 0.0, 1e-3
        )
        rows.append((K, sc, inv_cond_kkt(p, q, qd), fn))
    knees = np.linspace(0.3, 0.0, 31)
    knee_rows = []
    for kn in knees:
        qq = model3_q(stance_knee=kn)
        c = base.chain(0)
        knee_rows.append((kn, schur(base, qq, np.zeros(6))[0], inv_cond_kkt(base, qq, np.zeros(6))))
    return np.array(rows), np.array(knee_rows), k_star


def grazing():
    p = paper_biped()
    ch = p.chain(0)
    q = model3_q()
    J = kin.point_jacobian(ch, q, 5, HEEL)
    out = []
    for vz in (-1.0, -0.1, -1e-2, -1e-3, -1e-4, 0.0):
        qd = np.linalg.pinv(J) @ np.array([0.3, vz])
        qd_plus = nb_impact(ch.packed, ch.packed_scalars, 1, q, qd, 1)
        out.append(
            {
                "heel_vz_mps": vz,
                "velocity_change_norm": float(np.linalg.norm(qd_plus - qd)),
                "energy_lost_J": float(dyn.energy(ch, q, qd)[0] - dyn.energy(ch, q, qd_plus)[0]),
            }
        )
    return out


@command("failure_modes")
def main(argv=None) -> int:
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--out",
        type=Path,
        default=Path("runs/failure_modes"),
        help=f"output folder (default: runs/failure_modes; {RESULTS} updates the committed ones)",
    )
    out = ap.parse_args(argv).out
    with command_output(out, "failure_modes") as co:
        _run(Path(co.dir().where()))
    print(f"wrote {out}")
    return 0


def _run(out_dir: Path) -> None:
    """The study, its figures and JSON written into ``out_dir`` (a staging directory)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, knee_rows, k_star = conditioning()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    ax = axes[0]
    ax.plot(rows[:, 0], np.abs(rows[:, 1]), label="|Schur complement J_c M^-1 J_f^T|")
    ax.plot(rows[:, 0], rows[:, 2], label="1 / cond(KKT)")
    ax.set_yscale("log")
    if np.isfinite(k_star):
        ax.axvline(k_star, color="tab:red", ls="--", label=f"K* = {k_star:.2f}")
    ax.set_xlabel("friction ratio K (heel sliding forward at 2 m/s)")
    ax.set_title("model 3: KKT singular where the Schur complement crosses 0")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.plot(knee_rows[:, 0], knee_rows[:, 1], label="Schur complement (K = 0.5, no slip)")
    ax.plot(knee_rows[:, 0], knee_rows[:, 2], label="1 / cond(KKT)")
    ax.set_yscale("log")
    ax.set_xlabel("stance knee bend [rad] (0 = straight)")
    ax.set_title("straight knee: the solve stays regular")
    ax.invert_xaxis()
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out_dir / "conditioning.png", dpi=110)
    v = np.linspace(-0.01, 0.01, 401)
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(v * 1e3, np.sign(v), label="paper: v/|v| (discontinuous)")
    for eps in (1e-4, 1e-3, 3e-3):
        ax.plot(
            v * 1e3,
            v / np.sqrt(v * v + eps * eps),
            label=f"v/sqrt(v^2+eps^2), eps = {eps * 1e3:g} mm/s",
        )
    ax.set_xlabel("slip speed [mm/s]")
    ax.set_ylabel("friction direction (times K f_n)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out_dir / "friction_law.png", dpi=110)
    graz = grazing()
    out = {
        "painleve_K_star": k_star,
        "knee_min_inverse_condition": float(knee_rows[:, 2].min()),
        "inverse_condition_at_K_0.5": float(np.interp(0.5, rows[:, 0], rows[:, 2])),
        "grazing": graz,
    }
    write_file(out_dir / "failure_modes.json", json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    raise SystemExit(main())
