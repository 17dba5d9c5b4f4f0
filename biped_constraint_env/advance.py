"""The compiled advance loop of the hybrid simulator.

One control period of one simulator (:func:`nb_advance_w`: steps, guards, located events,
reset maps at model switches, ending on an out-of-model event), of N simulators in one call
(:func:`nb_advance_batch`, threaded from ``PARALLEL_MIN_BATCH`` rows), and the compiled start
of slots (:func:`nb_start_batch`).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit

from .hybrid import (
    FC_SLIP,
    FO_STEP_TOL,
    IO_IMPACT,
    IO_INTEGRATOR,
    IO_JDOT_FD,
    IO_LOCATE,
    IO_MAX_SWITCHES,
    IO_STOP_AT_SWITCH,
    IO_STRICT,
    IO_SUBSTEPS,
    N_FORCES,
    W_QDD,
    nb_evaluate_w,
    nb_impact,
    nb_make_work,
    nb_project_w,
    nb_renumber,
)
from .jit import njit_alloc, njit_noalloc
from .kinematics import nb_keypoints
from .model import COL_DAMPING
from .modes import FORCE_EVENTS, N_GUARDS, EventCode, packed_mode_table
from .state import (
    FS_DAMPED,
    FS_H,
    FS_ROOT,
    FS_T,
    FS_WORK_ABS,
    FS_WORK_POS,
    ST_IGNORED,
    ST_MODE,
    ST_SIDE,
    ST_STEPS,
    STATUS_OK,
)
from .stepper import (
    EVENT_STEP_FRACTION,
    H_MIN_S,
    LIMEX,
    RK4_LIMEX_ADAPTIVE,
    S_F,
    S_G,
    S_G1,
    S_K1,
    S_Q1,
    S_QD1,
    S_QDH,
    S_QH,
    S_TAU6,
    SEMI_IMPLICIT,
    _finite,
    _fired,
    _first_step,
    _next_step,
    _step_error,
    _step_length,
    nb_integrate_w,
    nb_locate_w,
    nb_make_scratch,
)

EV_MODE_SWITCH = int(EventCode.MODE_SWITCH)
EV_BEHIND = int(EventCode.STEP_BEHIND_STANCE_TOE)
EV_ZENO = int(EventCode.ZENO)
"""Event codes the period records itself (plain ints: numba freezes them as constants)."""

_SU, _RS = packed_mode_table()[3:5]


SUCCESSOR = tuple(int(x) for x in _SU)
RESET = tuple(int(x) for x in _RS)
FORCE_EVENT_FLAGS = tuple(int(EventCode(k) in FORCE_EVENTS) for k in range(N_GUARDS))


EVENT_PRIORITY = (5, 2, 3, 4, 1, 6, 7, 8)
"""Order in which simultaneous out-of-model guards are reported: geometry before forces."""


@njit_noalloc
def _record(ev, nev, t, code, mfrom, mto, terminal):
    if nev < ev.shape[0]:
        ev[nev, 0] = t
        ev[nev, 1] = code
        ev[nev, 2] = mfrom
        ev[nev, 3] = mto
        ev[nev, 4] = terminal
        return nev + 1
    return nev


@njit_alloc
def _reset_map(chs, scs, side, reset, q, qd, root_y, iopt):
    """The reset map of a model switch, in place on (q, qd): (heel behind, side, root_y).

    ``reset`` 1 (touchdown of the swing heel): if the swing heel is behind the stance toe the
    switch is refused (returns True: the run ends); else the impact. ``reset`` 2 (the swing
    foot lands flat): the impact, then the renumbering (paper eq. 25-29), which swaps ``side``
    and moves ``root_y`` to the new stance toe. Allocates, so it is kept out of the
    reference-count-free stepping loop (module jit), which calls it only at switches.
    """
    ch = chs[side]
    sc = scs[side]
    if reset == 1:
        heel_y = nb_keypoints(ch, sc, q, root_y)[7, 0]
        if heel_y < root_y:
            return True, side, root_y
        qd[:] = nb_impact(ch, sc, 1, q, qd, iopt[IO_IMPACT])
    elif reset == 2:
        qd[:] = nb_impact(ch, sc, 2, q, qd, iopt[IO_IMPACT])
        qn, qdn, root_y = nb_renumber(ch, chs[1 - side], sc, q, qd, root_y)
        q[:] = qn
        qd[:] = qdn
        side = 1 - side
    return False, side, root_y


@njit_noalloc
def _add_work(ch, fst, tau6, q0, qd0, qdd0, q1, qd1, qdd1, h):
    """Add one physics step's work to ``fst``: motors' positive and absolute, damping's.

    Over a step the motor torques hold, so joint j's work is exactly tau_j (q1_j - q0_j); its
    positive part (the step's net work where it is positive) and its absolute value are
    summed over the five motors. The damping's dissipation, the integral of D_j qd_j^2 over
    the step (all six joints), is Simpson's rule with the mid-step rate of the cubic Hermite
    interpolant of the ends' rates and accelerations, (qd0 + qd1) / 2 + h (qdd0 - qdd1) / 8.
    """
    pos = 0.0
    ab = 0.0
    for j in range(1, 6):
        w = tau6[j] * (q1[j] - q0[j])
        if w > 0.0:
            pos += w
        ab += abs(w)
    damp = 0.0
    for j in range(6):
        mid = 0.5 * (qd0[j] + qd1[j]) + 0.125 * h * (qdd0[j] - qdd1[j])
        damp += ch[j, COL_DAMPING] * (qd0[j] * qd0[j] + 4.0 * mid * mid + qd1[j] * qd1[j])
    fst[FS_WORK_POS] += pos
    fst[FS_WORK_ABS] += ab
    fst[FS_DAMPED] += h * damp / 6.0


@njit_noalloc
# One function of ~170 lines on purpose: the period's event loop (integrate, locate, impact,
# switch, renumber) shares a dozen scalars per iteration; numba compiles it as one loop with
# no calls that return tuples, which keeps the period allocation-free (test_jit).
def nb_advance_w(chs, scs, q, qd, ist, fst, tau_table, dt, iopt, fopt, a, b, ev, forces, W, S):
    """Advance one simulator by one control period dt [s], in place.

    Args:
        chs, scs: (2, 6, 6), (2, 8) packed chains of both numberings.
        q, qd: (6,) state, updated in place. ist: int64 [mode, side, steps, ignored-mask];
        fst: float64 (N_FST,) [t, root_y, next step, the work sums], updated in place.
        tau_table: (4, 5) joint torques [N m] for models 1..4 (a row per model; the torque
            switches with the model).
        iopt, fopt, a, b: packed options and integrator tableau.
        ev: (MAX_EVENTS, 5) event buffer (t, code, from, to, terminal), filled from row 0.
        forces: (5,) output: contact forces at the final state.
        W, S: workspace and scratch (nb_make_work, nb_make_scratch).

    Returns:
        (status, number of events): status 0 running, 1 terminated, 2 non-finite.
    """
    mode = ist[ST_MODE]
    side = ist[ST_SIDE]
    steps = ist[ST_STEPS]
    ignored = ist[ST_IGNORED]
    t = fst[FS_T]
    root_y = fst[FS_ROOT]
    t_end = t + dt
    h_nom = dt / iopt[IO_SUBSTEPS]
    strict = iopt[IO_STRICT] != 0
    nev = 0
    status = 0
    switches = 0
    check = True
    tau6 = S[S_TAU6]
    g = S[S_G]
    g1 = S[S_G1]
    fo = S[S_F]
    k1 = S[S_K1]
    # first-same-as-last: the accelerations of the last evaluation at the current state are
    # the first stage of the next explicit step (not with the paper's finite-difference J-dot,
    # whose sample length changes with the step, nor for the implicit methods)
    explicit = iopt[IO_INTEGRATOR] != SEMI_IMPLICIT and iopt[IO_INTEGRATOR] != LIMEX
    reuse = iopt[IO_JDOT_FD] == 0 and explicit
    step_tol = fopt[FO_STEP_TOL]
    adaptive = iopt[IO_INTEGRATOR] == RK4_LIMEX_ADAPTIVE
    h_try = _first_step(fst, h_nom, adaptive)
    while True:
        ch = chs[side]
        sc = scs[side]
        for j in range(5):
            tau6[j + 1] = tau_table[mode - 1, j]
        k = -1
        if check:
            nb_evaluate_w(ch, sc, mode, q, qd, tau6, iopt, fopt, 0.0, W, fo, g)
            for j in range(6):
                k1[j] = W[W_QDD][j]
            k1[6] = fo[FC_SLIP]
            for kk in EVENT_PRIORITY:
                if _fired(g, kk, ignored):
                    k = kk
                    break
            if k < 0 and _fired(g, 0, ignored):
                k = 0
            check = False
        if k < 0:
            if t_end - t <= 1e-9 * dt:
                break
            hh = _step_length(t_end - t, h_try, h_nom) if adaptive else min(h_nom, t_end - t)
            used = nb_integrate_w(ch, sc, mode, q, qd, tau6, hh, iopt, fopt, a, b, W, S, reuse)
            q1 = S[S_Q1]
            qd1 = S[S_QD1]
            if not _finite(q1, qd1):
                if adaptive and hh > H_MIN_S:
                    h_try = max(0.2 * hh, H_MIN_S)
                    continue
                status = 2
                break
            fd = hh if iopt[IO_JDOT_FD] != 0 else 0.0
            nb_evaluate_w(ch, sc, mode, q1, qd1, tau6, iopt, fopt, fd, W, fo, g1)
            if adaptive:
                accepted, h_try = _next_step(
                    _step_error(S, W, hh, used, step_tol), hh, h_try, h_nom, used
                )
                if not accepted:
                    continue
            mask = 0
            for kk in range(N_GUARDS):
                if _fired(g1, kk, ignored):
                    mask |= 1 << kk
            if mask == 0:
                _add_work(ch, fst, tau6, q, qd, k1, q1, qd1, W[W_QDD], hh)
                for j in range(6):
                    q[j] = q1[j]
                    qd[j] = qd1[j]
                    k1[j] = W[W_QDD][j]
                k1[6] = fo[FC_SLIP]
                for kk in range(N_GUARDS):
                    g[kk] = g1[kk]
                t += hh
                continue
            if iopt[IO_LOCATE] != 0:
                th = nb_locate_w(ch, sc, mode, q, qd, tau6, hh, mask, iopt, fopt, a, b, W, S, reuse)
                t += th * hh
                nb_evaluate_w(ch, sc, mode, S[S_QH], S[S_QDH], tau6, iopt, fopt, fd, W, fo, g1)
                _add_work(ch, fst, tau6, q, qd, k1, S[S_QH], S[S_QDH], W[W_QDD], th * hh)
                for j in range(6):
                    q[j] = S[S_QH][j]
                    qd[j] = S[S_QDH][j]
            else:
                t += hh
                _add_work(ch, fst, tau6, q, qd, k1, q1, qd1, W[W_QDD], hh)
                for j in range(6):
                    q[j] = q1[j]
                    qd[j] = qd1[j]
            for kk in EVENT_PRIORITY:
                if (mask >> kk) & 1 and g1[kk] <= 0.0:
                    k = kk
                    break
            if k < 0:
                if (mask & 1) and g1[0] <= 0.0:
                    k = 0
                else:
                    best = np.inf
                    for kk in range(N_GUARDS):
                        if (mask >> kk) & 1 and g1[kk] < best:
                            best = g1[kk]
                            k = kk
        # ---- handle event k at time t, state (q, qd)
        if k == EV_MODE_SWITCH:
            succ = SUCCESSOR[mode]
            behind, side, root_y = _reset_map(chs, scs, side, RESET[mode], q, qd, root_y, iopt)
            if behind:
                nev = _record(ev, nev, t, EV_BEHIND, mode, mode, 1)
                status = 1
                break
            nev = _record(ev, nev, t, EV_MODE_SWITCH, mode, succ, 0)
            if mode == 4:
                steps += 1
            mode = succ
            nb_project_w(chs[side], scs[side], mode, q, qd, W)
            ignored = 0
            switches += 1
            if adaptive:
                h_try = max(h_nom * EVENT_STEP_FRACTION, H_MIN_S)
            if switches > iopt[IO_MAX_SWITCHES]:
                nev = _record(ev, nev, t, EV_ZENO, mode, mode, 1)
                status = 1
                break
            check = True
            if iopt[IO_STOP_AT_SWITCH] != 0:
                # hand control back at the switch: forces of the new model at the new state
                # with its torque row (its guards are checked when the next period starts)
                for j in range(5):
                    tau6[j + 1] = tau_table[mode - 1, j]
                nb_evaluate_w(chs[side], scs[side], mode, q, qd, tau6, iopt, fopt, 0.0, W, fo, g)
                break
        else:
            terminal = strict or FORCE_EVENT_FLAGS[k] == 0
            nev = _record(ev, nev, t, k, mode, mode, 1 if terminal else 0)
            if terminal:
                status = 1
                break
            ignored |= 1 << k
            check = True
    # the last evaluation (at an accepted step's end, at an event, or the check after a reset)
    # was made at the final state with the final model's torques: its forces are the output
    if status != 2:
        for j in range(N_FORCES):
            forces[j] = fo[j]
    ist[ST_MODE] = mode
    ist[ST_SIDE] = side
    ist[ST_STEPS] = steps
    ist[ST_IGNORED] = ignored
    fst[FS_T] = t
    fst[FS_ROOT] = root_y
    fst[FS_H] = h_try if adaptive else 0.0
    return status, nev


@njit(cache=True)
def nb_advance(chs, scs, q, qd, ist, fst, tau_table, dt, iopt, fopt, a, b, ev, forces):
    """:func:`nb_advance_w` with a fresh workspace (one simulator, one control period)."""
    return nb_advance_w(
        chs,
        scs,
        q,
        qd,
        ist,
        fst,
        tau_table,
        dt,
        iopt,
        fopt,
        a,
        b,
        ev,
        forces,
        nb_make_work(),
        nb_make_scratch(),
    )


@njit(cache=True)
def _advance_range(
    chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, lo, hi
):
    """:func:`nb_advance_w` over rows lo..hi-1 with one workspace; rows with STATUS != 0 skip."""
    _advance_rows(
        chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, lo, hi,
        nb_make_work(), nb_make_scratch(),
    )  # fmt: skip


@njit_noalloc
def _advance_rows(
    chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, lo, hi, W, S
):
    """The rows' loop of :func:`_advance_range`, given its workspace and scratch."""
    for i in range(lo, hi):
        if STATUS[i] != 0:
            NEV[i] = 0
            continue
        STATUS[i], NEV[i] = nb_advance_w(
            chs,
            scs,
            Q[i],
            QD[i],
            IST[i],
            FST[i],
            TAU[i],
            dt,
            iopt,
            fopt,
            a,
            b,
            EV[i],
            FORCES[i],
            W,
            S,
        )


@njit(cache=True)
def nb_advance_batch(chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV):
    """:func:`nb_advance_w` over N simulators (rows of every array); skips rows with STATUS != 0."""
    _advance_range(
        chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, 0, Q.shape[0]
    )


@njit(cache=True, parallel=True)
def nb_advance_batch_parallel(
    chs, scs, Q, QD, IST, FST, TAU, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, nt
):
    """:func:`nb_advance_batch` split into ``nt`` chunks, one per thread (same results)."""
    n = Q.shape[0]
    chunk = (n + nt - 1) // nt
    for c in numba.prange(nt):
        _advance_range(
            chs,
            scs,
            Q,
            QD,
            IST,
            FST,
            TAU,
            dt,
            iopt,
            fopt,
            a,
            b,
            EV,
            FORCES,
            STATUS,
            NEV,
            c * chunk,
            min(n, (c + 1) * chunk),
        )


PARALLEL_MIN_BATCH = 8
"""Batches at least this large are stepped by the multi-threaded kernel."""


@njit(cache=True)
def nb_start_batch(chs, scs, Q, QD, IST, FST, FORCES, STATUS, NEV, idx, modes, iopt, fopt):
    """Start slots ``idx`` (their Q, QD set) in ``modes``; returns each one's lowest point z [m].

    Leg A stands with its toe at y = 0 and t = 0, no step completed. Computes the contact
    forces at zero torque (for the first observation) and clears the status and event count.
    The caller rejects states whose lowest point is below ground.
    """
    W = nb_make_work()
    g = np.empty(N_GUARDS)
    tau6 = np.zeros(6)
    low = np.empty(idx.shape[0])
    for k in range(idx.shape[0]):
        i = idx[k]
        IST[i, :] = 0
        IST[i, ST_MODE] = modes[k]
        FST[i, :] = 0.0
        side = IST[i, ST_SIDE]
        pts = nb_keypoints(chs[side], scs[side], Q[i], FST[i, FS_ROOT])
        low[k] = pts[:, 1].min()
        nb_evaluate_w(
            chs[side],
            scs[side],
            IST[i, ST_MODE],
            Q[i],
            QD[i],
            tau6,
            iopt,
            fopt,
            0.0,
            W,
            FORCES[i],
            g,
        )
        STATUS[i] = STATUS_OK
        NEV[i] = 0
    return low
