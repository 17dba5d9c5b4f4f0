"""The environments' control period as one compiled call: physics, observation and reward.

:class:`~.env.ConstrainedBipedEnv` and :class:`~.vector_env.ConstrainedBipedVectorEnv` both
step through :func:`nb_env_period`: the torque check (:func:`~.actions.nb_check_torques`), the
simulator's :func:`~.simulator.nb_advance_w`, the observation
(:func:`~.observation.nb_observe_row`) and the per-period record every reward kind reads
(:data:`~.rewards.N_RECORD`: the "env" reward's terms, :func:`~.rewards.nb_reward_terms`, where
it is the reward; the progress, switches, steps, torque and swing-ankle speed), so they agree
bit for bit, and a single ``env.step`` enters compiled code once. The Python around
it checks the action's shape and dtype and builds ``info``.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit

from .actions import (
    PCFG_NSUB,
    TORQUE_ACTIONS,
    nb_check_torques,
    nb_pd_targets,
    nb_pd_torques,
)
from .advance import PARALLEL_MIN_BATCH, nb_advance_w
from .hybrid import IO_STOP_AT_SWITCH, nb_make_work
from .jit import njit_noalloc
from .kinematics import K_VY, NK
from .model import N_ACTUATED, N_LINKS
from .observation import OBS_DIM, OBS_HIGH, OBS_LOW, nb_observe, nb_observe_row
from .rewards import (
    CFG_ENV,
    N_ENV_TERMS,
    N_RECORD,
    REC_ALIVE,
    REC_PROGRESS,
    REC_STEPS,
    REC_SWING_VY,
    REC_SWITCHES,
    REC_TAU_SQ,
    nb_cycle_position,
    nb_fallen,
    nb_reward_terms,
)
from .simulator import SimArrays
from .state import (
    FS_T,
    ST_MODE,
    ST_STEPS,
    STATUS_NONFINITE,
    STATUS_OK,
    STATUS_TERMINATED,
)
from .stepper import nb_make_scratch


@njit(cache=True)
def _period_range(robot, state, numerics, io, cfgs, lo, hi):
    """:func:`nb_env_period` for rows lo..hi-1, one workspace (the bundles: its docstring)."""
    EV = state[4]
    work = (
        nb_make_work(), nb_make_scratch(), np.empty((N_LINKS, NK)), np.empty((4, N_ACTUATED)),
        np.empty((EV.shape[1], EV.shape[2])), np.empty(N_ACTUATED), np.empty(N_ACTUATED),
    )  # fmt: skip
    _period_rows(robot, state, numerics, io, cfgs, lo, hi, work)


@njit_noalloc
def _pd_period(row, pd, numerics, work):
    """One control period of PD targets: the PD law at each of ``pcfg[0]`` physics steps.

    ``row``: the row's (chs, scs, q, qd, ist, fst, ev, forces); ``pd``: (base, rate, pcfg,
    act, tgt); ``numerics``: (dt, iopt, fopt, a, b); ``work``: (W, S, table, evs, tau). The
    action ``act`` (5,) in [-1, 1] sets the targets ``tgt`` = ``base`` + range x act
    (:func:`~.actions.nb_pd_targets`); they and their rates ``rate`` (5,) hold over the
    period; before every physics step of dt / n the torques are
    :func:`~.actions.nb_pd_torques` of the current state (the same in every model). A
    terminal event ends the period, and so does a model switch when the options stop at
    switches. ``act`` (5,) receives the time-mean torque [N m]; returns (status, events,
    time-mean of sum(tau^2) [N^2 m^2]). Events of all the physics steps are collected in
    ``ev`` (``evs``: a scratch of its shape).
    """
    chs, scs, q, qd, ist, fst, ev, forces = row
    base, rate, pcfg, act, tgt = pd
    dt, iopt, fopt, a, b = numerics
    W, S, table, evs, tau = work
    n_sub = int(pcfg[PCFG_NSUB])
    h = dt / n_sub
    stop_at_switch = iopt[IO_STOP_AT_SWITCH] != 0
    nev = 0
    status = 0
    sq = 0.0
    span = 0.0
    nb_pd_targets(base, act, pcfg, tgt)
    for j in range(N_ACTUATED):
        act[j] = 0.0
    for s in range(n_sub):
        nb_pd_torques(tgt, rate, q, qd, pcfg, tau)
        for m in range(4):
            for j in range(N_ACTUATED):
                table[m, j] = tau[j]
        mode = ist[ST_MODE]
        ts = fst[FS_T]
        status, ne = nb_advance_w(
            chs, scs, q, qd, ist, fst, table, h, iopt, fopt, a, b, evs, forces, W, S
        )  # fmt: skip
        for r in range(ne):
            if nev < ev.shape[0]:
                for c in range(ev.shape[1]):
                    ev[nev, c] = evs[r, c]
                nev += 1
        tau_sq = 0.0
        for j in range(N_ACTUATED):
            tau_sq += tau[j] * tau[j]
        if s == 0:  # exact for one step: the held law of earlier versions, bit for bit
            sq = tau_sq
            for j in range(N_ACTUATED):
                act[j] = tau[j]
            span = fst[FS_T] - ts
        else:
            w = fst[FS_T] - ts
            tot = span + w
            if tot > 0.0:
                sq = (sq * span + tau_sq * w) / tot
                for j in range(N_ACTUATED):
                    act[j] = (act[j] * span + tau[j] * w) / tot
            span = tot
        if status != 0 or (stop_at_switch and ist[ST_MODE] != mode):
            break
    return status, nev, sq


@njit_noalloc
def _period_rows(robot, state, numerics, io, cfgs, lo, hi, work):
    """The rows' loop of :func:`_period_range`, given its workspaces.

    ``work``: (W, S, K, table, evs, tau, tgt): :func:`~.hybrid.nb_make_work`,
    :func:`~.simulator.nb_make_scratch`, K (6, NK) the observation's kinematics, table (4, 5)
    the torque table (the action holds in every model), and the PD period's scratch.
    """
    CHS, SCS = robot
    Q, QD, IST, FST, EV, FORCES, STATUS, NEV = state
    dt, iopt, fopt, a, b = numerics
    ACT, OBS, HIP, REW, FELL, TGT, RATE = io
    cfg, pcfg, acfg = cfgs
    W, S, K, table, evs, tau, tgt = work
    pd = pcfg[PCFG_NSUB] > 0
    for i in range(lo, hi):
        chs = CHS[i]  # the row's robot (its own masses, damping, K: model randomisation)
        scs = SCS[i]
        hip0 = HIP[i, 0]
        pos0 = nb_cycle_position(IST[i, ST_MODE], IST[i, ST_STEPS])
        steps0 = IST[i, ST_STEPS]
        tau_sq = -1.0  # torque actions: the reward squares ACT[i]
        if STATUS[i] == STATUS_OK and pd:
            STATUS[i], NEV[i], tau_sq = _pd_period(
                (chs, scs, Q[i], QD[i], IST[i], FST[i], EV[i], FORCES[i]),
                (TGT[i], RATE[i], pcfg, ACT[i], tgt), numerics, (W, S, table, evs, tau),
            )  # fmt: skip
        elif STATUS[i] == STATUS_OK:
            for m in range(4):
                for j in range(N_ACTUATED):
                    table[m, j] = ACT[i, j]
            STATUS[i], NEV[i] = nb_advance_w(
                chs, scs, Q[i], QD[i], IST[i], FST[i], table, dt, iopt, fopt, a, b, EV[i],
                FORCES[i], W, S,
            )  # fmt: skip
        else:
            NEV[i] = 0
            if pd:  # not stepped: the torques its targets would ask for now
                nb_pd_targets(TGT[i], ACT[i], pcfg, tgt)
                nb_pd_torques(tgt, RATE[i], Q[i], QD[i], pcfg, ACT[i])
        nb_observe_row(
            chs, scs, Q[i], QD[i], IST[i], FST[i], FORCES[i], OBS[i], HIP[i], OBS_LOW, OBS_HIGH, K
        )
        if STATUS[i] < 0:
            REW[i, :] = 0.0
            FELL[i] = 0
            continue
        fell = STATUS[i] == STATUS_OK and nb_fallen(HIP[i, 1], cfg)
        FELL[i] = 1 if fell else 0
        terminated = STATUS[i] == STATUS_TERMINATED or STATUS[i] == STATUS_NONFINITE or fell
        if tau_sq < 0.0:  # torque actions: the held torques' sum of squares
            tau_sq = 0.0
            for j in range(N_ACTUATED):
                tau_sq += ACT[i, j] * ACT[i, j]
        rec = REW[i]  # the period's record, read by every reward kind
        rec[REC_PROGRESS] = HIP[i, 0] - hip0
        rec[REC_SWITCHES] = nb_cycle_position(IST[i, ST_MODE], IST[i, ST_STEPS]) - pos0
        rec[REC_STEPS] = IST[i, ST_STEPS] - steps0
        rec[REC_ALIVE] = 0.0 if terminated else 1.0
        rec[REC_TAU_SQ] = tau_sq
        rec[REC_SWING_VY] = K[5, K_VY]  # the swing ankle's, from the observation's pass
        if cfg[CFG_ENV] != 0.0:  # the "env" reward's terms, only where they are the reward
            nb_reward_terms(rec[REC_PROGRESS], dt, rec[REC_SWITCHES], rec[REC_STEPS],
                            not terminated, ACT[i], cfg, rec[:N_ENV_TERMS], tau_sq)  # fmt: skip
        else:
            for c in range(N_ENV_TERMS):
                rec[c] = 0.0


@njit(cache=True)
def nb_env_period(robot, state, numerics, io, cfgs):
    """One control period of N environments (rows), serially; 0, or 1 if a torque is refused.

    Its arrays come in five bundles:

    * ``robot`` (CHS (n, 2, 6, 6), SCS (n, 2, 8)): each row's packed robot
      (:attr:`~.model.BipedParams.packed`; rows differ under model randomisation);
    * ``state`` (Q, QD, IST, FST, EV, FORCES, STATUS, NEV): the simulator's arrays
      (:class:`~.simulator.SimArrays`); rows with STATUS != 0 are not advanced;
    * ``numerics`` (dt, iopt, fopt, a, b): the control period [s] and the packed
      :class:`~.options.SimOptions`;
    * ``io`` (ACT, OBS, HIP, REW, FELL, TGT, RATE): ACT (n, 5), the actions (torques [N m],
      held over the period in every model; PD targets in [-1, 1] when ``pcfg[0] > 0``, then
      written: each row's time-mean torque); OBS (n, 24) and HIP (n, 4), the observation and
      hip kinematics, read before (progress) and written after the period; REW (n, 12), written:
      the per-period record (:data:`~.rewards.N_RECORD`; zeros for rows whose STATUS is
      negative: resetting, not stepped); FELL (n,), written: 1 where the hip fell below the
      fall height; TGT, RATE (n, 5): the PD targets' base [rad] and rates [rad/s];
    * ``cfgs`` (cfg, pcfg, acfg): :func:`~.rewards.reward_config`,
      :func:`~.actions.pd_config`, :func:`~.actions.action_config`.

    ACT is checked (and clipped) first, every row, by :func:`~.actions.nb_check_torques` with
    ``acfg``; if it refuses one, nothing else is done and 1 is returned.
    """
    if nb_check_torques(io[0], cfgs[2]) != 0:
        return 1
    _period_range(robot, state, numerics, io, cfgs, 0, state[0].shape[0])
    return 0


@njit(cache=True, parallel=True)
def nb_env_period_parallel(robot, state, numerics, io, cfgs, nt):
    """:func:`nb_env_period` split into ``nt`` chunks of rows, one per thread (same results)."""
    if nb_check_torques(io[0], cfgs[2]) != 0:
        return 1
    n = state[0].shape[0]
    chunk = (n + nt - 1) // nt
    for c in numba.prange(nt):
        _period_range(robot, state, numerics, io, cfgs, c * chunk, min(n, (c + 1) * chunk))
    return 0


class EnvBuffers:
    """The arrays one compiled period reads and writes for N environments.

    ``sim`` (:class:`~.simulator.SimArrays`), ``act`` (n, 5) the actions [N m], ``obs``
    (n, 24), ``hip`` (n, 4: hip y, z, vy, vz), ``rew`` (n, 12: the per-period record)
    and ``fell`` (n,). :meth:`period` runs :func:`nb_env_period` on them; batches of at least
    ``PARALLEL_MIN_BATCH`` rows given ``num_threads`` > 1 are split among that many numba
    threads (:func:`nb_env_period_parallel`).

    The arrays are this object's own, allocated once, so their numba types never change: the
    kernels are compiled (or loaded from the cache) for those types at construction, and a
    period calls the compiled entry point with the arguments bound then, without numba's
    per-call type dispatch (about 1 us of a 20 us ``env.step``).
    """

    def __init__(
        self,
        n: int,
        params,
        options,
        dt: float,
        cfg: np.ndarray,
        acfg: np.ndarray,
        num_threads: int = 1,
        pcfg: np.ndarray = TORQUE_ACTIONS,
    ):
        """Allocate for ``n`` environments of a robot, physics, period [s] and settings.

        ``cfg``: :func:`~.rewards.reward_config`; ``acfg``: :func:`~.actions.action_config`;
        ``num_threads``: numba threads that step a batch of at least ``PARALLEL_MIN_BATCH``
        rows (1: serial); ``pcfg``: :func:`~.actions.pd_config` (PD targets in ``tgt`` and
        ``rate``) or :data:`~.actions.TORQUE_ACTIONS` (torques in ``act``).
        """
        self.sim = SimArrays(n)
        self.act = np.zeros((n, N_ACTUATED))
        self.tgt = np.zeros((n, N_ACTUATED))
        self.rate = np.zeros((n, N_ACTUATED))
        self.pcfg = np.array(pcfg, dtype=np.float64)
        self.obs = np.zeros((n, OBS_DIM))
        self.hip = np.zeros((n, 4))
        self.rew = np.zeros((n, N_RECORD))
        self.fell = np.zeros(n, np.int64)
        chs, scs = params.packed
        self.chs = np.repeat(chs[None], n, axis=0)  # each row's robot (set_params changes one)
        self.scs = np.repeat(scs[None], n, axis=0)
        iopt, fopt, a, b = options.packed
        s = self.sim
        self._args = (
            (self.chs, self.scs),
            (s.q, s.qd, s.ist, s.fst, s.events, s.forces, s.status, s.n_events),
            (float(dt), iopt, fopt, a, b),
            (self.act, self.obs, self.hip, self.rew, self.fell, self.tgt, self.rate),
            (cfg, self.pcfg, acfg),
        )  # a few bundles (nb_env_period)
        self.num_threads = int(num_threads)
        self._parallel = n >= PARALLEL_MIN_BATCH and self.num_threads > 1
        self._observe_args = (
            self.chs, self.scs, s.q, s.qd, s.ist, s.fst, s.forces, self.obs, self.hip, OBS_LOW,
            OBS_HIGH,
        )  # fmt: skip
        self._bind()

    def _bind(self) -> None:
        self._serial = _entry_point(nb_env_period, self._args)
        self._threaded = (
            _entry_point(nb_env_period_parallel, (*self._args, 2)) if self._parallel else None
        )
        self._observe = _entry_point(nb_observe, self._observe_args)

    def __getstate__(self) -> dict:
        """Picklable state: the arrays (entry points are rebound on unpickling)."""
        return {k: v for k, v in self.__dict__.items() if k not in _ENTRY_POINTS}

    def __setstate__(self, state: dict) -> None:
        """Restore the arrays and bind the compiled entry points again."""
        self.__dict__.update(state)
        self._bind()

    def set_params(self, i: int, params) -> None:
        """Row ``i`` steps the robot ``params`` (:class:`~.model.BipedParams`) from now on."""
        self.chs[i], self.scs[i] = params.packed

    def period(self) -> int:
        """One period of every row: 0, or 1 if a torque in ``act`` is refused (nothing done).

        Checks (and clips) the torques, then advances every running row, observes and rewards
        every row.
        """
        if self._parallel:
            return self._threaded(*self._args, self.num_threads)
        return self._serial(*self._args)

    def observe(self) -> None:
        """Fill ``obs`` and ``hip`` from the current states (after a reset)."""
        self._observe(*self._observe_args)


_ENTRY_POINTS = ("_serial", "_threaded", "_observe")


def _entry_point(dispatcher, args: tuple):
    """The compiled entry point of a numba ``dispatcher`` for the numba types of ``args``."""
    return dispatcher.compile(tuple(numba.typeof(x) for x in args))
