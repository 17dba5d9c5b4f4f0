"""Solving one model, its guards, and the reset maps between models (compiled core).

- :func:`nb_solve_mode_w`: the one constrained solve of paper eq. 9 for every model,
  ``[[M + h_imp D, -(J_c - K s J_t)^T], [J_c, 0]] [qdd; f_n] = [tau - b - D qd; gamma]``,
  restricted to the model's unknowns (theta0 dropped in models 1 and 4, f_n only with a point
  contact), solved by LU with partial pivoting (never an inverse). One forward pass gives M
  (CRBA), the bias b = INV(q, qd, 0, g) (backward pass) and the exact J-dot q-dot.
- :func:`nb_evaluate_w`: the solve plus the contact forces and the guard vector (see
  :mod:`biped_constraint_env.modes` for the sign convention).
- Reset maps: :func:`nb_impact` (``"paper"``: all joint velocities zero; ``"plastic"``: the
  impulse that brings the new contact to rest, kinetic energy never increases) and
  :func:`nb_renumber` (paper eq. 25-29: the chain re-rooted at the new stance toe; every link's
  world pose and angular velocity unchanged).
- :func:`nb_project_w`: projection of the point contact back onto ``z = 0`` (positions,
  Euclidean Newton steps) and of the velocities onto ``J_z qd = 0`` (kinetic-energy metric).

Functions suffixed ``_w`` take a workspace from :func:`nb_make_work` and allocate nothing.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .contact import nb_contact_rows
from .dynamics import nb_crba, nb_mass_matrix, nb_rnea_backward
from .jit import njit_noalloc
from .kinematics import (
    K_COS,
    K_OY,
    K_OZ,
    K_PHI,
    K_SIN,
    NK,
    nb_fk,
    nb_fk_accelerations,
    nb_forward_pass,
    nb_point_jacobian,
)
from .model import (
    COL_ANGLE,
    COL_DAMPING,
    SC_FOOT0_MASS,
    SC_FRICTION,
    SC_GRAVITY,
    SC_GRAVITY_T,
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
IO_PROJECT, IO_MAX_SWITCHES, IO_MASS_RNEA, IO_STOP_AT_SWITCH = 7, 8, 9, 10
N_IOPT = 11
FO_SLIP_EPS, FO_POS_TOL, FO_TIME_TOL, FO_STEP_TOL = range(4)
N_FOPT = 4
IMPACT_PAPER, IMPACT_PLASTIC = 0, 1

# Contact-force vector filled by nb_evaluate_w.
FC_TOE, FC_HEEL, FC_CONTACT, FC_STANCE_Y, FC_SLIP = range(5)
N_FORCES = 5

# Workspace layout (a tuple of arrays).
(W_K, W_KP, W_M, W_TMP, W_F, W_N, W_A, W_R, W_JAC, W_JACP, W_QDD, W_Z6, W_CNT, W_E, W_X, W_QP) = (
    range(16)
)

INF = math.inf

# Guard indices as plain ints for the compiled code (= the EventCode values).
G_TIPS_BACK = int(EventCode.STANCE_FOOT_TIPS_BACK)
G_HEEL_DOWN = int(EventCode.STANCE_HEEL_DOWN)
G_TOE_STRIKE = int(EventCode.SWING_TOE_STRIKE)
G_TOUCHDOWN = int(EventCode.SWING_FOOT_TOUCHDOWN)
G_BELOW_GROUND = int(EventCode.BODY_BELOW_GROUND)
G_HEEL_PULLS = int(EventCode.SWING_HEEL_PULLS)
G_TOE_PULLS = int(EventCode.STANCE_TOE_PULLS)
G_FOOT_PULLS = int(EventCode.STANCE_FOOT_PULLS)


@njit(cache=True)
def nb_make_work():
    """A fresh workspace for the ``_w`` functions (zeroed views of one allocation)."""
    buf = np.zeros(2 * 6 * NK + 36 + 24 + 12 + 6 + 49 + 7 + 12 + 12 + 6 + 6 + 1 + 6 + 18 + 6)
    return (
        buf[0 : 6 * NK].reshape((6, NK)),  # K: forward pass at the current state
        buf[6 * NK : 12 * NK].reshape((6, NK)),  # Kp: at the previous sample (FD J-dot)
        nb_carve(buf, 12 * NK, 6, 6),  # M
        nb_carve(buf, 12 * NK + 36, 4, 6),  # CRBA scratch
        nb_carve(buf, 12 * NK + 60, 6, 2),  # joint forces
        buf[12 * NK + 72 : 12 * NK + 78],  # joint moments / bias
        nb_carve(buf, 12 * NK + 78, 7, 7),  # KKT matrix
        buf[12 * NK + 127 : 12 * NK + 134],  # KKT right-hand side / solution
        nb_carve(buf, 12 * NK + 134, 2, 6),  # point Jacobian
        nb_carve(buf, 12 * NK + 146, 2, 6),  # point Jacobian at the previous sample
        buf[12 * NK + 158 : 12 * NK + 164],  # qdd
        buf[12 * NK + 164 : 12 * NK + 170],  # zeros (never written)
        buf[12 * NK + 170 : 12 * NK + 171],  # count of constrained solves (cost accounting)
        buf[12 * NK + 171 : 12 * NK + 177],  # unit vector scratch (mass matrix by NE columns)
        nb_carve(buf, 12 * NK + 177, 6, 3),  # three right-hand sides (implicit friction)
        buf[12 * NK + 195 : 12 * NK + 201],  # q at the previous sample (FD J-dot)
    )


@njit(cache=True)
def nb_carve(buf, start, rows, cols):
    """The (rows, cols) C-contiguous view of ``buf[start : start + rows * cols]``."""
    return buf[start : start + rows * cols].reshape((rows, cols))


def wrap_angles(a):
    """Angles (array or scalar) wrapped to [-pi, pi) [rad], in numpy (for Python callers)."""
    return (a + np.pi) % (2 * np.pi) - np.pi


@njit_noalloc
def nb_wrap(a):
    """Angle wrapped to (-pi, pi] [rad]."""
    return a - 2.0 * math.pi * math.ceil((a - math.pi) / (2.0 * math.pi))


@njit_noalloc
def nb_lu_solve_inplace(m, x, n):
    """Solve the leading n x n block of m against x[:n] in place (LU, partial pivoting).

    m is destroyed; x holds the solution. Returns the pivot ratio min|u_ii| / max|u_ii|, a
    cheap conditioning indicator (0: singular).
    """
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
    return umin / umax if umax > 0.0 else 0.0


@njit_noalloc
def nb_lu_solve_multi(m, x, n, nr):
    """:func:`nb_lu_solve_inplace` for the nr right-hand sides in the columns of x[:n, :nr].

    Kept apart from the one-right-hand-side solve of every evaluation: routing that through
    this function (x viewed as (n, 1)) made a model-3 evaluation 1.4x slower (0.74 -> 1.04 us).
    """
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
            for c in range(nr):
                t = x[k, c]
                x[k, c] = x[p, c]
                x[p, c] = t
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
                for c in range(nr):
                    x[i, c] -= f * x[k, c]
    for c in range(nr):
        for k in range(n - 1, -1, -1):
            s = x[k, c]
            for j in range(k + 1, n):
                s -= m[k, j] * x[j, c]
            x[k, c] = s / m[k, k]
    return umin / umax if umax > 0.0 else 0.0


@njit(cache=True)
def nb_lu_solve(a, b):
    """Solve a x = b (small dense; allocating); returns (x, pivot ratio)."""
    m = a.copy()
    x = b.copy()
    piv = nb_lu_solve_inplace(m, x, b.shape[0])
    return x, piv


@njit_noalloc
def nb_mass_matrix_columns_w(ch, q, W):
    """M into W[W_M] column by column, INV(q, 0, e_i, 0) (paper eq. 14), leaving W[W_K] dirty."""
    K = W[W_K]
    e = W[W_E]
    z6 = W[W_Z6]
    M = W[W_M]
    col = W[W_N]
    for i in range(6):
        for j in range(6):
            e[j] = 0.0
        e[i] = 1.0
        nb_fk(ch, q, z6, e, 0.0, K)
        nb_rnea_backward(ch, K, 0.0, 0.0, -1, 0.0, 0.0, 0.0, W[W_F], col)
        for j in range(6):
            M[j, i] = col[j]


@njit_noalloc
def nb_solve_mode_w(
    ch, sc, mode, q, qd, tau6, h_imp, jdot_fd_h, slip_eps, W, mass_rnea=False, implicit_fric=False
):
    """The constrained solve of paper eq. 9 for ``mode`` (1..4); qdd goes to W[W_QDD].

    Args:
        ch, sc: packed chain and scalars. q, qd: (6,) state. tau6: (6,) joint torques, tau6[0]=0.
        h_imp: step [s] with which the damping is treated implicitly (0: plain dynamics).
        jdot_fd_h: 0 for the exact J-dot q-dot; > 0 for the paper's backward difference.
        slip_eps: friction regularisation speed [m/s].
        W: workspace.
        mass_rnea: the mass matrix by Newton-Euler columns (paper eq. 14) instead of CRBA.
        implicit_fric: with h_imp > 0 and a point contact, also take the friction's
            direction at the step's end, ``s(v + h_imp J_t qdd)`` (see
            :func:`_solve_implicit_friction`).

    Returns:
        f_n [N] (0 without contact), slip sign s, pivot ratio of the factorisation.
    """
    K = W[W_K]
    M = W[W_M]
    A = W[W_A]
    r = W[W_R]
    jac = W[W_JAC]
    qdd = W[W_QDD]
    z6 = W[W_Z6]
    s0 = 1 - ROOT_FREE[mode]
    n = 6 - s0
    col = CONTACT_COL[mode]
    nc = 1 if col >= 0 else 0
    W[W_CNT][0] += 1.0
    if mass_rnea:
        nb_mass_matrix_columns_w(ch, q, W)
        nb_fk(ch, q, qd, z6, 0.0, K)
    else:
        nb_fk(ch, q, qd, z6, 0.0, K)
        nb_crba(ch, K, M, W[W_TMP])
    b = W[W_N]
    nb_rnea_backward(ch, K, sc[SC_GRAVITY], sc[SC_GRAVITY_T], -1, 0.0, 0.0, 0.0, W[W_F], b)
    for i in range(n):
        di = ch[s0 + i, COL_DAMPING]
        for j in range(n):
            A[i, j] = M[s0 + i, s0 + j]
        A[i, i] += h_imp * di
        r[i] = tau6[s0 + i] - b[s0 + i] - di * qd[s0 + i]
    sg = 0.0
    if nc == 1:
        if jdot_fd_h > 0.0:
            qp = W[W_QP]
            for j in range(6):
                qp[j] = q[j] - jdot_fd_h * qd[j]
            nb_fk(ch, qp, z6, z6, 0.0, W[W_KP])
        gamma, sg = nb_contact_rows(K, W[W_KP], qd, sc[col], slip_eps, jdot_fd_h, jac, W[W_JACP])
        fric = sc[SC_FRICTION] * sg
        if implicit_fric and h_imp > 0.0:
            return _solve_implicit_friction(sc, s0, n, qd, h_imp, slip_eps, gamma, sg, W)
        for i in range(n):
            A[i, n] = -(jac[1, s0 + i] - fric * jac[0, s0 + i])
            A[n, i] = jac[1, s0 + i]
        A[n, n] = 0.0
        r[n] = gamma
    piv = nb_lu_solve_inplace(A, r, n + nc)
    for i in range(6):
        qdd[i] = r[i - s0] if i >= s0 else 0.0
    fn = r[n] if nc == 1 else 0.0
    return fn, sg, piv


@njit_noalloc
def _slip_residual(w, v, h, s, eps, kf, P, U, Wt, Pc, Uc, Wc):
    """Residual (scaled by h) of the slip speed w at the step's end, and its f_n and sigma."""
    sigma = w / math.sqrt(w * w + eps * eps) - s
    fn = -Pc / (Uc - kf * sigma * Wc)
    return w - v - h * (P + fn * (U - kf * sigma * Wt)), fn, sigma


@njit_noalloc
def _solve_implicit_friction(sc, s0, n, qd, h, eps, gamma, sg, W):
    """The point-contact solve with the friction direction taken at the step's end.

    With A = M + h D (its leading n x n block in W[W_A]), c = J_c - K s J_t and
    sigma = s(v + h J_t qdd) - s(v) (v the slip speed, s the regularised sign):
    ``A qdd = r + c f - K f sigma J_t`` and ``J_c qdd = gamma``. With p, u, w = A^-1 (r, c, J_t)
    (one factorisation, three right-hand sides), f = -(J_c p - gamma) / (J_c u - K sigma J_c w)
    and the end slip speed solves one scalar equation, bracketed and closed by Illinois regula
    falsi: the friction force stays bounded by K f_n, however stiff the regularisation.
    """
    A = W[W_A]
    r = W[W_R]
    jac = W[W_JAC]
    qdd = W[W_QDD]
    X = W[W_X]
    kf = sc[SC_FRICTION]
    v = 0.0
    for i in range(6):
        v += jac[0, i] * qd[i]
    for i in range(n):
        X[i, 0] = r[i]
        X[i, 1] = jac[1, s0 + i] - kf * sg * jac[0, s0 + i]
        X[i, 2] = jac[0, s0 + i]
    piv = nb_lu_solve_multi(A, X, n, 3)
    P = U = Wt = Pc = Uc = Wc = 0.0
    for i in range(n):
        P += jac[0, s0 + i] * X[i, 0]
        U += jac[0, s0 + i] * X[i, 1]
        Wt += jac[0, s0 + i] * X[i, 2]
        Pc += jac[1, s0 + i] * X[i, 0]
        Uc += jac[1, s0 + i] * X[i, 1]
        Wc += jac[1, s0 + i] * X[i, 2]
    Pc -= gamma
    # bracket the end slip speed, starting from the explicit prediction
    lo = v + h * (P - Pc / Uc * U)
    rlo, fn, sigma = _slip_residual(lo, v, h, sg, eps, kf, P, U, Wt, Pc, Uc, Wc)
    step = max(eps, abs(lo - v))
    direction = -1.0 if rlo > 0.0 else 1.0
    hi = lo
    rhi = rlo
    for _ in range(80):
        hi = lo + direction * step
        rhi, fn, sigma = _slip_residual(hi, v, h, sg, eps, kf, P, U, Wt, Pc, Uc, Wc)
        if (rhi > 0.0) != (rlo > 0.0) or rhi == 0.0:
            break
        lo = hi
        rlo = rhi
        step *= 2.0
    side = 0
    for _ in range(100):
        if rhi == 0.0 or abs(hi - lo) <= 1e-12 * max(eps, abs(hi)):
            break
        w = (lo * rhi - hi * rlo) / (rhi - rlo)
        rw, fn, sigma = _slip_residual(w, v, h, sg, eps, kf, P, U, Wt, Pc, Uc, Wc)
        if (rw > 0.0) == (rhi > 0.0):
            hi = w
            rhi = rw
            if side == 1:
                rlo *= 0.5
            side = 1
        else:
            lo = w
            rlo = rw
            if side == -1:
                rhi *= 0.5
            side = -1
    rhi, fn, sigma = _slip_residual(hi, v, h, sg, eps, kf, P, U, Wt, Pc, Uc, Wc)
    for i in range(6):
        qdd[i] = 0.0
    for i in range(n):
        qdd[s0 + i] = X[i, 0] + fn * X[i, 1] - kf * fn * sigma * X[i, 2]
    return fn, sg, piv


@njit(cache=True)
def nb_solve_mode(ch, sc, mode, q, qd, tau6, h_imp, jdot_fd_h, slip_eps):
    """Allocating form of :func:`nb_solve_mode_w`: returns (qdd (6,), f_n, s, pivot ratio)."""
    W = nb_make_work()
    fn, sg, piv = nb_solve_mode_w(ch, sc, mode, q, qd, tau6, h_imp, jdot_fd_h, slip_eps, W)
    return W[W_QDD].copy(), fn, sg, piv


@njit_noalloc
def nb_foot_split(sc, f1z, n1, foot_weight):
    """Heel and toe vertical forces (F_L, F_R) [N] of a flat stance foot (paper eq. 18-19).

    ``f1z``, ``n1``: vertical force and moment at the ankle on the shank from the foot. With
    ``foot_weight`` the foot's own weight is added (it acts at the ankle, the foot's midpoint).
    """
    w = sc[SC_FOOT0_MASS] * sc[SC_GRAVITY] if foot_weight else 0.0
    half = 0.5 * (f1z + w)
    mom = n1 / sc[SC_SPLIT]
    return half - mom, half + mom


@njit_noalloc
def nb_evaluate_w(ch, sc, mode, q, qd, tau6, iopt, fopt, fd_h, W, forces, g):
    """Solve ``mode`` at (q, qd), then fill its contact forces and guards.

    ``forces`` (5,): stance toe, stance heel, point contact f_n, stance horizontal force [N],
    slip speed [m/s]. ``g`` (9,): index 0 the transition guard, k >= 1 the out-of-model guard
    of EventCode k (+inf where not applicable). qdd is left in W[W_QDD]. Returns the pivot ratio.
    """
    fn, sg, piv = nb_solve_mode_w(
        ch, sc, mode, q, qd, tau6, 0.0, fd_h, fopt[FO_SLIP_EPS], W, iopt[IO_MASS_RNEA] != 0
    )
    col = CONTACT_COL[mode]
    K = W[W_K]
    f = W[W_F]
    nmom = W[W_N]
    link = -1
    s_off = 0.0
    fy = 0.0
    fz = 0.0
    slip = 0.0
    if col >= 0:
        link = 5
        s_off = sc[col]
        fy = -sc[SC_FRICTION] * sg * fn
        fz = fn
        jac = W[W_JAC]  # still the contact Jacobian at q from the solve
        for j in range(6):
            slip += jac[0, j] * qd[j]
    nb_fk_accelerations(ch, W[W_QDD], K)  # K holds the solve's pass at (q, qd)
    nb_rnea_backward(ch, K, sc[SC_GRAVITY], sc[SC_GRAVITY_T], link, s_off, fy, fz, f, nmom)
    forces[FC_CONTACT] = fn
    forces[FC_STANCE_Y] = f[0, 0]
    forces[FC_SLIP] = slip
    for k in range(N_GUARDS):
        g[k] = INF
    tol = fopt[FO_POS_TOL]
    heel5_z = K[5, K_OZ] + sc[SC_HEEL5] * K[5, K_SIN]
    toe5_z = K[5, K_OZ] + sc[SC_TOE5] * K[5, K_SIN]
    if ROOT_FREE[mode] == 0:
        f_heel, f_toe = nb_foot_split(sc, f[1, 1], nmom[1], iopt[IO_FOOT_WEIGHT] != 0)
        forces[FC_HEEL] = f_heel
        forces[FC_TOE] = f_toe
    else:
        forces[FC_HEEL] = 0.0
        forces[FC_TOE] = f[0, 1]
    if mode == 1:
        g[0] = forces[FC_HEEL]
        g[G_TIPS_BACK] = forces[FC_TOE]
        g[G_TOUCHDOWN] = min(heel5_z, toe5_z) + tol
    elif mode == 2 or mode == 3:
        heel0_z = K[0, K_OZ] + sc[SC_HEEL0] * K[0, K_SIN]
        g[G_HEEL_DOWN] = heel0_z + tol
        g[G_TOE_PULLS] = forces[FC_TOE]
        if mode == 2:
            g[0] = heel5_z
            g[G_TOE_STRIKE] = toe5_z + tol
        else:
            g[0] = nb_wrap(K[5, K_PHI])
            g[G_HEEL_PULLS] = fn
    else:
        g[0] = fn
        g[G_HEEL_DOWN] = heel5_z + tol
        g[G_FOOT_PULLS] = min(forces[FC_HEEL], forces[FC_TOE])
    zmin = INF
    # knees and hip; an ankle is the midpoint of its foot's sole, so it can only go below the
    # floor through a foot end, which the foot guards catch. (Checking the swing ankle made a
    # flat landing, phi5 = 0 with the ankle exactly at z = 0, race the 3 -> 4 switch.)
    for k in range(2, 5):
        zmin = min(zmin, K[k, K_OZ])
    g[G_BELOW_GROUND] = zmin + tol
    return piv


@njit(cache=True)
def nb_evaluate(ch, sc, mode, q, qd, tau6, root_y, iopt, fopt, fd_h):
    """Allocating form of :func:`nb_evaluate_w`: returns (qdd, forces, guards, pivot ratio).

    ``root_y`` is accepted for symmetry with the state; guards and forces do not depend on it.
    """
    W = nb_make_work()
    forces = np.zeros(N_FORCES)
    g = np.empty(N_GUARDS)
    piv = nb_evaluate_w(ch, sc, mode, q, qd, tau6, iopt, fopt, fd_h, W, forces, g)
    return W[W_QDD].copy(), forces, g, piv


@njit_noalloc
def nb_project_w(ch, sc, mode, q, qd, W):
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
    K = W[W_K]
    jac = W[W_JAC]
    z6 = W[W_Z6]
    for _ in range(2):
        nb_fk(ch, q, z6, z6, 0.0, K)
        pz = K[5, K_OZ] + sc[col] * K[5, K_SIN]
        nb_jacobian_into_row(K, sc[col], jac)
        jj = 0.0
        for j in range(s0, 6):
            jj += jac[1, j] * jac[1, j]
        if jj <= 0.0:
            return
        for j in range(s0, 6):
            q[j] -= jac[1, j] * pz / jj
    nb_fk(ch, q, z6, z6, 0.0, K)
    nb_jacobian_into_row(K, sc[col], jac)
    n = 6 - s0
    M = W[W_M]
    nb_crba(ch, K, M, W[W_TMP])
    A = W[W_A]
    x = W[W_R]
    for i in range(n):
        x[i] = jac[1, s0 + i]
        for j in range(n):
            A[i, j] = M[s0 + i, s0 + j]
    nb_lu_solve_inplace(A, x, n)
    jx = 0.0
    jv = 0.0
    for i in range(n):
        jx += jac[1, s0 + i] * x[i]
        jv += jac[1, s0 + i] * qd[s0 + i]
    for i in range(n):
        qd[s0 + i] -= x[i] * jv / jx


@njit_noalloc
def nb_jacobian_into_row(K, s_off, jac):
    """Point Jacobian of offset s_off on link 5 (the only link carrying point contacts)."""
    py = K[5, K_OY] + s_off * K[5, K_COS]
    pz = K[5, K_OZ] + s_off * K[5, K_SIN]
    for j in range(6):
        jac[0, j] = -(pz - K[j, K_OZ])
        jac[1, j] = py - K[j, K_OY]


@njit(cache=True)
def nb_project(ch, sc, mode, q, qd):
    """Allocating form of :func:`nb_project_w`."""
    nb_project_w(ch, sc, mode, q, qd, nb_make_work())


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
    if reset == 1:
        jac = nb_point_jacobian(ch, q, 5, sc[SC_HEEL5])
        rows = np.empty((1, 6))
        rows[0] = jac[1]
    else:
        jac = nb_point_jacobian(ch, q, 5, 0.0)
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
