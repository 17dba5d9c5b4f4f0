"""Failure modes beyond the step size (benchmarks/failure_modes.py has the figures)."""

import dataclasses

import numpy as np
import pytest

from benchmarks.failure_modes import grazing, model3_q, schur
from biped_constraint_env import kinematics as kin
from biped_constraint_env.contact import nb_slip_sign
from biped_constraint_env.hybrid import nb_solve_mode
from biped_constraint_env.model import paper_biped


def test_friction_direction_regularised_and_continuous():
    v = np.linspace(-1e-2, 1e-2, 2001)
    s = np.array([nb_slip_sign(x, 1e-3) for x in v])
    assert s[1000] == 0.0  # no friction at zero slip (kinetic law, no stiction)
    assert np.all(np.abs(s) < 1) and np.all(np.diff(s) > 0)  # bounded, monotone: no jump
    assert s[-1] == pytest.approx(1.0, abs=1e-2) and s[0] == pytest.approx(-1.0, abs=1e-2)


def test_grazing_impact_impulse_vanishes_continuously():
    rows = grazing()
    dv = [r["velocity_change_norm"] for r in rows]
    assert dv[-1] < 1e-12  # no impact at zero approach speed
    assert dv[3] / dv[2] == pytest.approx(0.1, rel=1e-6)  # linear in the approach speed
    assert all(r["energy_lost_J"] >= 0 for r in rows)


def test_painleve_threshold_makes_the_kkt_singular():
    """The normal force needed changes sign across K* where the Schur complement vanishes."""
    base = paper_biped()
    q = model3_q()
    ch = base.chain(0)
    J = kin.point_jacobian(ch, q, 5, -0.25)
    qd = 2.0 * np.linalg.pinv(J[:1]) @ np.array([1.0])
    _, a, b = schur(base, q, qd)
    k_star = a / b
    fns = []
    for K in (0.9 * k_star, 1.1 * k_star):
        p = dataclasses.replace(base, friction_ratio=float(K))
        c = p.chain(0)
        fns.append(
            nb_solve_mode(c.packed, c.packed_scalars, 3, q, qd, np.zeros(6), 0.0, 0.0, 1e-3)[1]
        )
    assert np.sign(fns[0]) != np.sign(fns[1])
    p = dataclasses.replace(base, friction_ratio=float(k_star))
    assert abs(schur(p, q, qd)[0]) < 1e-9
