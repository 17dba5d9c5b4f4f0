"""Solving one model, its guards, and the reset maps between models (compiled core).

- :func:`nb_solve_mode`: the one constrained solve of paper eq. 9 for every model,
  ``[[M + h_imp D, -(J_c - K s J_t)^T], [J_c, 0]] [qdd; f_n] = [tau - b - D qd; gamma]``,
  restricted to the model's unknowns (theta0 dropped in models 1 and 4, f_n only with a point
  contact). It uses an LU factorisation with partial pivoting (never an inverse).
- :func:`nb_evaluate`: the solve plus the contact forces and the guard vector (see
  :mod:`biped_constraint_env.modes` for the sign convention).
- Reset maps: :func:`nb_impact` (``"paper"``: all joint velocities to zero; ``"plastic"``: the
  impulse that brings the new contact to rest, kinetic energy never increases) and
  :func:`nb_renumber` (paper eq. 25-29: the chain re-rooted at the new stance toe; every link's
  world pose and angular velocity unchanged).
- :func:`nb_project`: projection of the point contact back onto ``z = 0`` (positions, Euclidean
  Newton step) and of the velocities onto ``J_z qd = 0`` (in the kinetic-energy metric).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .contact import nb_contact_rows
from .dynamics import nb_mass_matrix, nb_rnea, nb_rnea_full
from .kinematics import nb_forward_pass, nb_point_jacobian
from .model import (
    COL_ANGLE,
    COL_DAMPING,
    SC_FOOT0_MASS,
    SC_FRICTION,
    SC_GRAVITY,
    SC_HEEL0,
    SC_HEEL5,
    SC_SPLIT,
    SC_TOE5,
)
from .modes import N_GUARDS, EventCode, packed_mode_table

_RF, _CT, _GD, _SU, _RS = packed_mode_table()
ROOT_FREE = tuple(int(x) for x in _RF)
CONTACT_COL = tuple(int(x) for x in _CT)

# Integer options (iopt) and float options (fopt) of the compiled core.
IO_INTEGRATOR, IO_SUBSTEPS, IO_IMPACT, IO_LOCATE, IO_JDOT_FD, IO_STRICT, IO_FOOT_WEIGHT = range(7)
IO_PROJECT, IO_MAX_SWITCHES = 7, 8
N_IOPT = 9
FO_SLIP_EPS, FO_POS_TOL, FO_TIME_TOL = range(3)
N_FOPT = 3
IMPACT_PAPER, IMPACT_PLASTIC = 0, 1

# Contact-force vector returned by nb_evaluate.
FC_TOE, FC_HEEL, FC_CONTACT, FC_STANCE_Y, FC_SLIP = range(5)
N_FORCES = 5

INF = math.inf


@njit(cache=True)
def nb_wrap(a):
    """Angle wrapped to (-pi, pi] [rad]."""
    return a - 2.0 * math.pi * math.ceil((a - math.pi) / (2.0 * math.pi))


@njit(cache=True)
def nb_lu_solve(a, b):
    """Solve a x = b (small dense) by LU with partial pivoting; returns (x, pivot ratio).

    The pivot ratio min|u_ii| / max|u_ii| is a cheap conditioning indicator (0: singular).
    """
    n = b.shape[0]
    m = a.copy()
    x = b.copy()
    umin = INF
    umax = 0.0
    for k in range(n):
        p = k
        big = abs(m[k, k])
        for i in range(k + 1, n):
            if abs(m[i, k]) > big:
                big = abs(m[i, k])
                p = i
        if p != k:
            for j in range(n):
                t = m[k, j]
                m[k, j] = m[p, j]
                m[p, j] = t
            t = x[k]
            x[k] = x[p]
            x[p] = t
        piv = m[k, k]
        umin = min(umin, abs(piv))
        umax = max(umax, abs(piv))
        if piv == 0.0:
            continue
        for i in range(k + 1, n):
            f = m[i, k] / piv
            if f != 0.0:
                for j in range(k + 1, n):
                    m[i, j] -= f * m[k, j]
                x[i] -= f * x[k]
    for k in range(n - 1, -1, -1):
        s = x[k]
        for j in range(k + 1, n):
            s -= m[k, j] * x[j]
        x[k] = s / m[k, k]
    return x, (umin / umax if umax > 0.0 else 0.0)


@njit(cache=True)
def nb_solve_mode(ch, sc, mode, q, qd, tau6, h_imp, jdot_fd_h, slip_eps):
    """The constrained solve of paper eq. 9 for ``mode`` (1..4).

    Args:
        ch, sc: packed chain and scalars. q, qd: (6,) state. tau6: (6,) joint torques, tau6[0]=0.
        h_imp: step [s] with which the damping is treated implicitly (0: plain dynamics).
        jdot_fd_h: 0 for the exact J-dot q-dot; > 0 for the paper's backward difference.
        slip_eps: friction regularisation speed [m/s].

    Returns:
        qdd (6,) [rad/s^2] (qdd[0] = 0 in models 1 and 4), f_n [N] (0 without contact),
        slip sign s, pivot ratio of the factorisation.
    """
    s0 = 1 - ROOT_FREE[mode]
    n = 6 - s0
    col = CONTACT_COL[mode]
    nc = 1 if col >= 0 else 0
    z6 = np.zeros(6)
    kin = nb_forward_pass(ch, q, qd, z6, 0.0, 0.0)
    M = nb_mass_matrix(ch, q)
    b = nb_rnea(ch, q, qd, z6, sc[SC_GRAVITY])
    A = np.zeros((n + nc, n + nc))
    r = np.zeros(n + nc)
    for i in range(n):
        di = ch[s0 + i, COL_DAMPING]
        for j in range(n):
            A[i, j] = M[s0 + i, s0 + j]
        A[i, i] += h_imp * di
        r[i] = tau6[s0 + i] - b[s0 + i] - di * qd[s0 + i]
    sg = 0.0
    if nc == 1:
        if jdot_fd_h > 0.0:
            kin_prev = nb_forward_pass(ch, q - jdot_fd_h * qd, z6, z6, 0.0, 0.0)
        else:
            kin_prev = kin
        c_row, f_row, gamma, sg = nb_contact_rows(
            kin, q, qd, sc[col], sc[SC_FRICTION], slip_eps, jdot_fd_h, kin_prev
        )
        for i in range(n):
            A[i, n] = -f_row[s0 + i]
            A[n, i] = c_row[s0 + i]
        r[n] = gamma
    x, piv = nb_lu_solve(A, r)
    qdd = np.zeros(6)
    for i in range(n):
        qdd[s0 + i] = x[i]
    fn = x[n] if nc == 1 else 0.0
    return qdd, fn, sg, piv


@njit(cache=True)
def nb_foot_split(sc, f1z, n1, foot_weight):
    """Heel and toe vertical forces (F_L, F_R) [N] of a flat stance foot (paper eq. 18-19).

    ``f1z``, ``n1``: vertical force and moment at the ankle on the shank from the foot. With
    ``foot_weight`` the foot's own weight is added (it acts at the ankle, the foot's midpoint).
    """
    w = sc[SC_FOOT0_MASS] * sc[SC_GRAVITY] if foot_weight else 0.0
    half = 0.5 * (f1z + w)
    mom = n1 / sc[SC_SPLIT]
    return half - mom, half + mom


@njit(cache=True)
def nb_evaluate(ch, sc, mode, q, qd, tau6, root_y, iopt, fopt, fd_h):
    """Solve ``mode`` at (q, qd) and evaluate its contact forces and guards.

    Returns:
        qdd (6,), forces (5,) [N, N, N, N, m/s] (toe, heel, contact f_n, stance horizontal
        force, slip speed), guards (9,) (index 0: transition guard; k >= 1: out-of-model
        guard of EventCode k; +inf where not applicable), pivot ratio.
    """
    qdd, fn, sg, piv = nb_solve_mode(ch, sc, mode, q, qd, tau6, 0.0, fd_h, fopt[FO_SLIP_EPS])
    col = CONTACT_COL[mode]
    ext = np.zeros(2)
    s_off = 0.0
    link = -1
    if col >= 0:
        link = 5
        s_off = sc[col]
        ext[0] = -sc[SC_FRICTION] * sg * fn
        ext[1] = fn
    tau_id, f, nmom = nb_rnea_full(ch, q, qd, qdd, sc[SC_GRAVITY], link, s_off, ext)
    kin = nb_forward_pass(ch, q, qd, np.zeros(6), root_y, 0.0)
    phi, w, al, o = kin[0], kin[1], kin[2], kin[3]
    forces = np.zeros(5)
    forces[FC_CONTACT] = fn
    forces[FC_STANCE_Y] = f[0, 0]
    g = np.full(N_GUARDS, INF)
    tol = fopt[FO_POS_TOL]
    c5 = math.cos(phi[5])
    s5 = math.sin(phi[5])
    heel5_z = o[5, 1] + sc[SC_HEEL5] * s5
    toe5_z = o[5, 1] + sc[SC_TOE5] * s5
    if col >= 0:
        jac = nb_point_jacobian(phi, o, 5, s_off)
        v = 0.0
        for j in range(6):
            v += jac[0, j] * qd[j]
        forces[FC_SLIP] = v
    if ROOT_FREE[mode] == 0:
        f_heel, f_toe = nb_foot_split(sc, f[1, 1], nmom[1], iopt[IO_FOOT_WEIGHT] != 0)
        forces[FC_HEEL] = f_heel
        forces[FC_TOE] = f_toe
    else:
        forces[FC_TOE] = f[0, 1]
    if mode == 1:
        g[0] = forces[FC_HEEL]
        g[EventCode.STANCE_FOOT_TIPS_BACK] = forces[FC_TOE]
        g[EventCode.SWING_FOOT_TOUCHDOWN] = min(heel5_z, toe5_z) + tol
    elif mode == 2 or mode == 3:
        heel0_z = o[0, 1] + sc[SC_HEEL0] * math.sin(phi[0])
        g[EventCode.STANCE_HEEL_DOWN] = heel0_z + tol
        g[EventCode.STANCE_TOE_PULLS] = forces[FC_TOE]
        if mode == 2:
            g[0] = heel5_z
            g[EventCode.SWING_TOE_STRIKE] = toe5_z + tol
        else:
            g[0] = nb_wrap(phi[5])
            g[EventCode.SWING_HEEL_PULLS] = fn
    else:
        g[0] = fn
        g[EventCode.STANCE_HEEL_DOWN] = heel5_z + tol
        g[EventCode.STANCE_FOOT_PULLS] = min(forces[FC_HEEL], forces[FC_TOE])
    zmin = INF
    for k in range(2, 6):  # knee, hip, knee, swing ankle (the stance ankle: heel-down guard)
        zmin = min(zmin, o[k, 1])
    g[EventCode.BODY_BELOW_GROUND] = zmin + tol
    return qdd, forces, g, piv


@njit(cache=True)
def nb_project(ch, sc, mode, q, qd):
    """Project (q, qd) onto model ``mode``'s constraints in place.

    theta0 and its rate are set to zero in the flat-foot models; a point contact is brought
    back to z = 0 by two Euclidean Newton steps on q, and its vertical velocity to zero by the
    kinetic-energy-metric projection qd -= M^-1 J^T (J qd) / (J M^-1 J^T).
    """
    s0 = 1 - ROOT_FREE[mode]
    if s0 == 1:
        q[0] = 0.0
        qd[0] = 0.0
    col = CONTACT_COL[mode]
    if col < 0:
        return
    z6 = np.zeros(6)
    for _ in range(2):
        phi, w, al, o, vo, ao = nb_forward_pass(ch, q, z6, z6, 0.0, 0.0)
        pz = o[5, 1] + sc[col] * math.sin(phi[5])
        jac = nb_point_jacobian(phi, o, 5, sc[col])
        jj = 0.0
        for j in range(s0, 6):
            jj += jac[1, j] * jac[1, j]
        if jj <= 0.0:
            return
        for j in range(s0, 6):
            q[j] -= jac[1, j] * pz / jj
    phi, w, al, o, vo, ao = nb_forward_pass(ch, q, z6, z6, 0.0, 0.0)
    jac = nb_point_jacobian(phi, o, 5, sc[col])
    n = 6 - s0
    M = nb_mass_matrix(ch, q)
    Ms = np.empty((n, n))
    jrow = np.empty(n)
    for i in range(n):
        jrow[i] = jac[1, s0 + i]
        for j in range(n):
            Ms[i, j] = M[s0 + i, s0 + j]
    x, piv = nb_lu_solve(Ms, jrow)
    jx = 0.0
    jv = 0.0
    for i in range(n):
        jx += jrow[i] * x[i]
        jv += jrow[i] * qd[s0 + i]
    for i in range(n):
        qd[s0 + i] -= x[i] * jv / jx


@njit(cache=True)
def nb_impulse(ch, q, qd, rows):
    """Plastic impulse: qd+ = qd - M^-1 C^T (C M^-1 C^T)^-1 C qd, over all six joints.

    ``rows`` (k, 6) are the velocity constraints of the new contact; afterwards C qd+ = 0 and
    the kinetic energy has decreased by the energy of the removed velocity component.
    """
    k = rows.shape[0]
    M = nb_mass_matrix(ch, q)
    minv_ct = np.empty((6, k))
    for c in range(k):
        x, piv = nb_lu_solve(M, rows[c].copy())
        minv_ct[:, c] = x
    S = np.zeros((k, k))
    cv = np.zeros(k)
    for r in range(k):
        for j in range(6):
            cv[r] += rows[r, j] * qd[j]
            for c in range(k):
                S[r, c] += rows[r, j] * minv_ct[j, c]
    lam, piv = nb_lu_solve(S, cv)
    out = qd.copy()
    for j in range(6):
        for c in range(k):
            out[j] -= minv_ct[j, c] * lam[c]
    return out


@njit(cache=True)
def nb_impact(ch, sc, reset, q, qd, impact):
    """Velocity reset on entering model 3 (reset 1) or model 4 (reset 2), in the old chain.

    ``impact`` 0 (``"paper"``): all joint velocities zero. 1 (``"plastic"``): reset 1 brings
    the swing heel's vertical velocity to zero (it may slide); reset 2 brings the swing foot to
    rest (ankle velocity and foot angular velocity zero) with the stance toe still pinned.
    """
    if impact == IMPACT_PAPER:
        return np.zeros(6)
    z6 = np.zeros(6)
    phi, w, al, o, vo, ao = nb_forward_pass(ch, q, z6, z6, 0.0, 0.0)
    if reset == 1:
        jac = nb_point_jacobian(phi, o, 5, sc[SC_HEEL5])
        rows = np.empty((1, 6))
        rows[0] = jac[1]
    else:
        jac = nb_point_jacobian(phi, o, 5, 0.0)
        rows = np.empty((3, 6))
        rows[0] = jac[0]
        rows[1] = jac[1]
        rows[2] = 1.0
    return nb_impulse(ch, q, qd, rows)


@njit(cache=True)
def nb_renumber(ch, ch_new, sc, q, qd, root_y):
    """Re-root the chain at the swing toe (paper eq. 25-29); returns (q', qd', root_y').

    The new link j is the old link 5 - j, traversed the other way for the legs (direction
    + pi) and the same way for the feet (heel -> toe). Joint angles are recomputed from the
    absolute link directions, so every link's world pose and angular velocity are unchanged.
    ``ch_new`` is the chain in the new numbering (for its angle offsets).
    """
    z6 = np.zeros(6)
    phi, w, al, o, vo, ao = nb_forward_pass(ch, q, qd, z6, root_y, 0.0)
    phi_new = np.empty(6)
    w_new = np.empty(6)
    for j in range(6):
        phi_new[j] = phi[5 - j] + (0.0 if (j == 0 or j == 5) else math.pi)
        w_new[j] = w[5 - j]
    q_new = np.empty(6)
    qd_new = np.empty(6)
    prev = 0.0
    wprev = 0.0
    for j in range(6):
        q_new[j] = nb_wrap(phi_new[j] - prev - ch_new[j, COL_ANGLE])
        qd_new[j] = w_new[j] - wprev
        prev = phi_new[j]
        wprev = w_new[j]
    root_new = o[5, 0] + sc[SC_TOE5] * math.cos(phi[5])
    return q_new, qd_new, root_new
