"""One integration step of the current model, and what surrounds it in the compiled loop.

The integrators' step (explicit, LIMEX, RK4_LIMEX), its error estimate and next-step control,
and the location of a guard crossing inside a step (Illinois regula falsi on a Hermite
interpolant).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .contact import nb_slip_sign
from .hybrid import (
    CONTACT_COL,
    FO_SLIP_EPS,
    FO_TIME_TOL,
    IO_INTEGRATOR,
    IO_JDOT_FD,
    IO_MASS_RNEA,
    IO_PROJECT,
    N_FORCES,
    W_QDD,
    nb_carve,
    nb_evaluate_w,
    nb_make_work,
    nb_project_w,
    nb_solve_mode_w,
)
from .integrators import (
    EVALS_PER_STEP,
    Integrator,
    friction_is_stiff,
)
from .jit import njit_noalloc
from .modes import N_GUARDS, packed_mode_table
from .state import FS_H, N_FST

MAX_LOCATE_ITERATIONS = 100
"""Safety cap on root-finding iterations (the tolerance is normally met in < 20)."""
H_MIN_S = 1e-6
"""Smallest error-controlled step [s]: a step this short is accepted whatever its estimate,
and no step is proposed shorter (so that a period takes at most about dt / H_MIN_S steps)."""


RATE_ERROR_WEIGHT_S = 0.05
"""How a rate error counts in the error-controlled step's estimate: as the angle [rad] it
moves a link over this time [s] (or over the step, if longer). Rates matter beyond the angles
they move: a controller observes them every period. At 5 ms control the walking network's
outcomes on seeds 0-9 agree with those under fixed 2.5 ms steps (and 0.31 ms, seeds 0 and 4)
when the estimate per step stays below 2e-4 rad and 4e-3 rad/s; with rates weighted by the
step alone (5 ms, 4e-2 rad/s) they do not (a 36th step in most episodes, a fall in one;
docs/speed_accuracy.md)."""
EVENT_STEP_FRACTION = 0.1
"""The error-controlled first step after a model switch, as a fraction of the largest step:
an impact starts fast transients (the new contact's slip, the damped joints), which a step
sized for the motion before it would only meet with rejections."""


_RF = packed_mode_table()[0]


N_STAGES = tuple(EVALS_PER_STEP[Integrator(m)] for m in range(len(Integrator)))
SEMI_IMPLICIT = int(Integrator.SEMI_IMPLICIT)
LIMEX = int(Integrator.LIMEX)
RK4_LIMEX = int(Integrator.RK4_LIMEX)
RK4_LIMEX_ADAPTIVE = int(Integrator.RK4_LIMEX_ADAPTIVE)


S_KQ, S_KV, S_QS, S_VS, S_Q1, S_QD1, S_QH, S_QDH, S_G, S_G1, S_TAU6, S_F, S_K1 = range(13)


@njit(cache=True)
def nb_make_scratch():
    """Scratch arrays of the stepping loop (zeroed views of one allocation)."""
    buf = np.zeros(24 + 24 + 6 * 6 + 2 * N_GUARDS + 6 + N_FORCES + 7)
    g = 84 + 2 * N_GUARDS
    return (
        nb_carve(buf, 0, 4, 6),  # kq: stage velocities
        nb_carve(buf, 24, 4, 6),  # kv: stage accelerations
        buf[48:54],  # stage q
        buf[54:60],  # stage qd
        buf[60:66],  # q after a step
        buf[66:72],  # qd after a step
        buf[72:78],  # q at the bracket's upper end (event location)
        buf[78:84],  # qd at the bracket's upper end
        buf[84 : 84 + N_GUARDS],  # guards
        buf[84 + N_GUARDS : g],  # guards after a step
        buf[g : g + 6],  # tau6
        buf[g + 6 : g + 6 + N_FORCES],  # forces scratch
        buf[g + 6 + N_FORCES : g + 13 + N_FORCES],  # qdd at the start state (first RK stage,
        # reused), slip speed
    )


@njit_noalloc
def _limex_step(ch, sc, mode, q, qd, tau6, h, fd, eps, W, S, mr):
    """One LIMEX step of h into S[S_Q1], S[S_QD1].

    y_a is one linearly implicit Euler step of h, y_b two of h / 2, and y1 = 2 y_b - y_a.
    """
    q1 = S[S_Q1]
    qd1 = S[S_QD1]
    qdd = W[W_QDD]
    qa = S[S_KQ][0]
    va = S[S_KV][0]
    qs = S[S_QS]
    vs = S[S_VS]
    nb_solve_mode_w(ch, sc, mode, q, qd, tau6, h, fd, eps, W, mr, True)
    for j in range(6):
        va[j] = qd[j] + h * qdd[j]
        qa[j] = q[j] + h * va[j]
    h2 = 0.5 * h
    nb_solve_mode_w(ch, sc, mode, q, qd, tau6, h2, 0.5 * fd, eps, W, mr, True)
    for j in range(6):
        vs[j] = qd[j] + h2 * qdd[j]
        qs[j] = q[j] + h2 * vs[j]
    nb_solve_mode_w(ch, sc, mode, qs, vs, tau6, h2, 0.5 * fd, eps, W, mr, True)
    for j in range(6):
        qd1[j] = vs[j] + h2 * qdd[j]
        q1[j] = qs[j] + h2 * qd1[j]
        qd1[j] = 2.0 * qd1[j] - va[j]
        q1[j] = 2.0 * q1[j] - qa[j]


@njit_noalloc
# ~80 lines on purpose: the integrators' stages share the workspaces W and S in one compiled
# function (no allocation per step, test_jit); one branch per integrator, read top to bottom.
def nb_integrate_w(ch, sc, mode, q, qd, tau6, h, iopt, fopt, a, b, W, S, use_k1=False):
    """One integration step of length h [s] inside ``mode``; result in S[S_Q1], S[S_QD1].

    With ``use_k1`` the first explicit stage is taken from S[S_K1], the accelerations already
    evaluated at (q, qd) with the same torques (first-same-as-last reuse).
    """
    method = iopt[IO_INTEGRATOR]
    fd = h if iopt[IO_JDOT_FD] != 0 else 0.0
    eps = fopt[FO_SLIP_EPS]
    q1 = S[S_Q1]
    qd1 = S[S_QD1]
    qdd = W[W_QDD]
    used = 0
    if method == SEMI_IMPLICIT:
        used = 2
        nb_solve_mode_w(ch, sc, mode, q, qd, tau6, h, fd, eps, W, iopt[IO_MASS_RNEA] != 0)
        for j in range(6):
            qd1[j] = qd[j] + h * qdd[j]
            q1[j] = q[j] + h * qd1[j]
    elif method == LIMEX:
        used = 1
        _limex_step(ch, sc, mode, q, qd, tau6, h, fd, eps, W, S, iopt[IO_MASS_RNEA] != 0)
    else:
        ns = N_STAGES[method]
        kq = S[S_KQ]
        kv = S[S_KV]
        qs = S[S_QS]
        vs = S[S_VS]
        # stiffness switching: watch the slip sign at each stage state (start included)
        switching = (method == RK4_LIMEX or method == RK4_LIMEX_ADAPTIVE) and CONTACT_COL[mode] >= 0
        stiff = False
        s_first = 0.0
        if switching and use_k1:
            s_first = nb_slip_sign(S[S_K1][6], eps)
            stiff = friction_is_stiff(s_first, h)
        for st in range(ns):
            if stiff:
                break
            for j in range(6):
                qs[j] = q[j]
                vs[j] = qd[j]
            for k in range(st):
                c = h * a[st, k]
                if c != 0.0:
                    for j in range(6):
                        qs[j] += c * kq[k, j]
                        vs[j] += c * kv[k, j]
            if st == 0 and use_k1:
                for j in range(6):
                    kq[0, j] = qd[j]
                    kv[0, j] = S[S_K1][j]
                continue
            _, sg, _ = nb_solve_mode_w(
                ch, sc, mode, qs, vs, tau6, 0.0, fd, eps, W, iopt[IO_MASS_RNEA] != 0
            )
            if switching:
                if st == 0:
                    s_first = sg
                if friction_is_stiff(sg, h) or sg * s_first < 0.0:
                    stiff = True
                    break
            for j in range(6):
                kq[st, j] = vs[j]
                kv[st, j] = qdd[j]
        if stiff:
            used = 1
            _limex_step(ch, sc, mode, q, qd, tau6, h, fd, eps, W, S, iopt[IO_MASS_RNEA] != 0)
        else:
            for j in range(6):
                q1[j] = q[j]
                qd1[j] = qd[j]
            for st in range(ns):
                c = h * b[st]
                for j in range(6):
                    q1[j] += c * kq[st, j]
                    qd1[j] += c * kv[st, j]
    if iopt[IO_PROJECT] != 0:
        nb_project_w(ch, sc, mode, q1, qd1, W)
    elif _RF[mode] == 0:
        q1[0] = 0.0
        qd1[0] = 0.0
    return used


@njit(cache=True)
def nb_integrate(ch, sc, mode, q, qd, tau6, h, iopt, fopt, a, b):
    """Allocating form of :func:`nb_integrate_w`: returns the new (q, qd)."""
    W = nb_make_work()
    S = nb_make_scratch()
    nb_integrate_w(ch, sc, mode, q, qd, tau6, h, iopt, fopt, a, b, W, S)
    return S[S_Q1].copy(), S[S_QD1].copy()


@njit_noalloc
def _fired(g, k, ignored):
    if (ignored >> k) & 1:
        return False
    return g[k] <= 0.0 if k == 0 else g[k] < 0.0


@njit_noalloc
def _gmin(g, mask):
    v = np.inf
    for k in range(g.shape[0]):
        if (mask >> k) & 1:
            v = min(v, g[k])
    return v


@njit_noalloc
def _hermite(q0, v0, a0, q1, v1, a1, h, s, qs, vs):
    """State at s h (0 <= s <= 1) of a step (q0, v0) -> (q1, v1) of length h.

    Uses the accelerations a0, a1 at its ends: quintic Hermite in q, cubic Hermite in qd.
    """
    s2 = s * s
    s3 = s2 * s
    s4 = s3 * s
    s5 = s4 * s
    p0 = 1.0 - 10.0 * s3 + 15.0 * s4 - 6.0 * s5
    p1 = s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5
    p2 = 0.5 * (s2 - 3.0 * s3 + 3.0 * s4 - s5)
    p3 = 1.0 - p0
    p4 = -4.0 * s3 + 7.0 * s4 - 3.0 * s5
    p5 = 0.5 * (s3 - 2.0 * s4 + s5)
    c0 = 2.0 * s3 - 3.0 * s2 + 1.0
    c1 = s3 - 2.0 * s2 + s
    c2 = 1.0 - c0
    c3 = s3 - s2
    hh = h * h
    for j in range(6):
        qs[j] = p0 * q0[j] + p1 * h * v0[j] + p2 * hh * a0[j] + p3 * q1[j]
        qs[j] += p4 * h * v1[j] + p5 * hh * a1[j]
        vs[j] = c0 * v0[j] + c1 * h * a0[j] + c2 * v1[j] + c3 * h * a1[j]


@njit_noalloc
def nb_locate_w(ch, sc, mode, q, qd, tau6, h, mask, iopt, fopt, a, b, W, S, use_k1):
    """Earliest crossing in (0, h] of the guards in ``mask``; returns theta.

    On entry S[S_G] holds the guards at the start state (q, qd), S[S_Q1], S[S_QD1] and S[S_G1]
    the full step's end state and guards; on return S[S_QH], S[S_QDH] hold the state at
    theta h. Illinois regula falsi (with a bisection every fourth iteration) on
    G(theta) = min_k g_k(x(theta)), x(theta) being the integrator's step of length theta h from
    (q, qd); the bracket is closed to ``time_tol_s``.
    """
    fd = h if iopt[IO_JDOT_FD] != 0 else 0.0
    qh = S[S_QH]
    qdh = S[S_QDH]
    for j in range(6):
        qh[j] = S[S_Q1][j]
        qdh[j] = S[S_QD1][j]
    ghi = _gmin(S[S_G1], mask)
    glo = _gmin(S[S_G], mask)
    g = S[S_G1]
    fo = S[S_F]
    lo = 0.0
    hi = 1.0
    if not glo > 0.0:
        for j in range(6):
            qh[j] = q[j]
            qdh[j] = qd[j]
        return 0.0
    side = 0
    tol = fopt[FO_TIME_TOL] / h
    dense = iopt[IO_INTEGRATOR] == RK4_LIMEX_ADAPTIVE
    if dense:  # the end state and accelerations, kept for the interpolant
        for j in range(6):
            S[S_KQ][3, j] = S[S_Q1][j]
            S[S_KV][3, j] = S[S_QD1][j]
            S[S_KV][2, j] = W[W_QDD][j]
    for it in range(MAX_LOCATE_ITERATIONS):
        if hi - lo <= tol:
            break
        if it % 4 == 3:
            th = 0.5 * (lo + hi)  # a bisection now and then guarantees the bracket shrinks
        else:
            th = (lo * ghi - hi * glo) / (ghi - glo)
            th = min(max(th, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
        if dense:
            _hermite(q, qd, S[S_K1], S[S_KQ][3], S[S_KV][3], S[S_KV][2], h, th, S[S_QS], S[S_VS])
            if iopt[IO_PROJECT] != 0:
                nb_project_w(ch, sc, mode, S[S_QS], S[S_VS], W)
            xq = S[S_QS]
            xv = S[S_VS]
        else:
            nb_integrate_w(ch, sc, mode, q, qd, tau6, th * h, iopt, fopt, a, b, W, S, use_k1)
            xq = S[S_Q1]
            xv = S[S_QD1]
        nb_evaluate_w(ch, sc, mode, xq, xv, tau6, iopt, fopt, fd, W, fo, g)
        gt = _gmin(g, mask)
        if gt <= 0.0:
            hi = th
            ghi = gt
            for j in range(6):
                qh[j] = xq[j]
                qdh[j] = xv[j]
            if side == -1:
                glo *= 0.5
            side = -1
        else:
            lo = th
            glo = gt
            if side == 1:
                ghi *= 0.5
            side = 1
    return hi


@njit_noalloc
def _step_error(S, W, hh, used, tol):
    """Error estimate of the step of hh [s] just taken, relative to tol (accept when <= 1).

    ``used`` 1 (a LIMEX step): half the difference between the extrapolated result and the
    single linearly implicit Euler step, i.e. the error of the two half steps (first order
    in h^2, so conservative for the second-order result). Otherwise (an RK4 step): the
    difference between RK4 and the third-order solution of the same stages plus the
    end-state evaluation, h/6 (f(y1) - k4), with no extra evaluation (the end state is
    evaluated anyway, for its guards). Angles count in rad, rates in rad/s times the larger
    of hh and :data:`RATE_ERROR_WEIGHT_S`.
    """
    q1 = S[S_Q1]
    qd1 = S[S_QD1]
    e = 0.0
    w = max(hh, RATE_ERROR_WEIGHT_S)
    if used == 1:
        qa = S[S_KQ][0]
        va = S[S_KV][0]
        for j in range(6):
            e = max(e, 0.5 * abs(q1[j] - qa[j]), 0.5 * w * abs(qd1[j] - va[j]))
    else:
        kq = S[S_KQ][3]
        kv = S[S_KV][3]
        qdd1 = W[W_QDD]
        c = hh / 6.0
        for j in range(6):
            e = max(e, c * abs(qd1[j] - kq[j]), c * w * abs(qdd1[j] - kv[j]))
    return e / tol


@njit_noalloc
def _first_step(fst, h_nom, adaptive):
    """The period's first step: the controller's carried proposal, else h_nom."""
    if fst.shape[0] < N_FST:
        raise ValueError("fst must hold N_FST values (t, root_y, next step)")
    return min(fst[FS_H], h_nom) if adaptive and fst[FS_H] > 0.0 else h_nom


@njit_noalloc
def _finite(q, qd):
    for j in range(6):
        if not (np.isfinite(q[j]) and np.isfinite(qd[j])):
            return False
    return True


@njit_noalloc
def _step_length(left, h_try, h_nom):
    """The error-controlled step [s] with ``left`` [s] to the period's end.

    No sliver before the end: the step stretches by up to 10 %, or what is left is halved
    when it is under two steps.
    """
    if left > 1.1 * h_try or left > h_nom * (1.0 + 1e-9):
        return 0.5 * left if left < 2.0 * h_try else h_try
    return left


@njit_noalloc
def _next_step(err, hh, h_try, h_nom, used):
    """(accepted, next step [s]) after a step of hh [s] with relative error estimate err.

    Rejected (err > 1, NaN included, unless hh is already H_MIN_S): retake shorter, by
    0.9 err^(-1/p) but at least 0.2. Accepted: the next step grows by at most 4, up to h_nom;
    a step cut short by the period's end only ever shrinks the proposal; never below H_MIN_S
    (a step accepted at H_MIN_S with a large estimate would otherwise propose ever shorter ones).
    """
    expo = 0.5 if used == 1 else 0.25
    if not err <= 1.0 and hh > H_MIN_S:
        r = 0.9 * err**-expo
        return False, max(hh * (r if r >= 0.2 else 0.2), H_MIN_S)
    fac = 4.0 if err <= 0.0 else min(4.0, 0.9 * err**-expo)
    if hh < h_try:
        return True, max(min(h_try, hh * fac) if fac < 1.0 else h_try, H_MIN_S)
    return True, max(min(h_nom, hh * fac), H_MIN_S)
