"""The environments' control period as one compiled call: physics, observation and reward.

:class:`~.env.ConstrainedBipedEnv` and :class:`~.vector_env.ConstrainedBipedVectorEnv` both
step through :func:`nb_env_period`: the torque check (:func:`~.actions.nb_check_torques`), the
simulator's :func:`~.simulator.nb_advance_w`, the observation
(:func:`~.observation.nb_observe_row`) and the reward (:func:`~.rewards.nb_reward_terms`), so
they agree bit for bit, and a single ``env.step`` enters compiled code once. The Python around
it checks the action's shape and dtype and builds ``info``.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit

from .actions import nb_check_torques
from .advance import PARALLEL_MIN_BATCH, nb_advance_w
from .hybrid import nb_make_work
from .jit import njit_noalloc
from .kinematics import NK
from .model import N_ACTUATED, N_LINKS
from .observation import OBS_DIM, OBS_HIGH, OBS_LOW, nb_observe, nb_observe_row
from .rewards import nb_cycle_position, nb_fallen, nb_reward_terms
from .simulator import SimArrays
from .state import ST_MODE, ST_STEPS, STATUS_NONFINITE, STATUS_OK, STATUS_TERMINATED
from .stepper import nb_make_scratch

N_REWARD_OUT = 6
"""Columns of the reward output: the five REWARD_TERMS, then their sum."""


@njit(cache=True)
def _period_range(
    chs, scs, Q, QD, IST, FST, ACT, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, OBS, HIP, cfg,
    REW, FELL, lo, hi,
):  # fmt: skip
    """:func:`nb_env_period` for rows lo..hi-1, one workspace."""
    _period_rows(
        chs, scs, Q, QD, IST, FST, ACT, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, OBS, HIP,
        cfg, REW, FELL, lo, hi, nb_make_work(), nb_make_scratch(), np.empty((N_LINKS, NK)),
        np.empty((4, N_ACTUATED)),
    )  # fmt: skip


@njit_noalloc
def _period_rows(
    chs, scs, Q, QD, IST, FST, ACT, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, OBS, HIP, cfg,
    REW, FELL, lo, hi, W, S, K, table,
):  # fmt: skip
    """The rows' loop of :func:`_period_range`, given its workspaces.

    W, S: :func:`~.hybrid.nb_make_work`, :func:`~.simulator.nb_make_scratch`; K (6, NK): the
    observation's kinematics; table (4, 5): the torque table (the action holds in every model).
    """
    for i in range(lo, hi):
        hip0 = HIP[i, 0]
        pos0 = nb_cycle_position(IST[i, ST_MODE], IST[i, ST_STEPS])
        steps0 = IST[i, ST_STEPS]
        if STATUS[i] == STATUS_OK:
            for m in range(4):
                for j in range(N_ACTUATED):
                    table[m, j] = ACT[i, j]
            STATUS[i], NEV[i] = nb_advance_w(
                chs, scs, Q[i], QD[i], IST[i], FST[i], table, dt, iopt, fopt, a, b, EV[i],
                FORCES[i], W, S,
            )  # fmt: skip
        else:
            NEV[i] = 0
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
        nb_reward_terms(
            HIP[i, 0] - hip0,
            dt,
            nb_cycle_position(IST[i, ST_MODE], IST[i, ST_STEPS]) - pos0,
            IST[i, ST_STEPS] - steps0,
            not terminated,
            ACT[i],
            cfg,
            REW[i],
        )


@njit(cache=True)
def nb_env_period(
    chs, scs, Q, QD, IST, FST, ACT, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, OBS, HIP, cfg,
    REW, FELL, acfg,
):  # fmt: skip
    """One control period of N environments (rows), serially; 0, or 1 if a torque is refused.

    ACT (n, 5), the actions (torques [N m], held over the period in every model), is checked
    (and clipped) first, every row, by :func:`~.actions.nb_check_torques` with ``acfg``; if it
    refuses one, nothing else is done and 1 is returned. Arguments: the simulator's
    (:func:`~.simulator.nb_advance_batch`, with ACT for its torque tables), then OBS (n, 24)
    and HIP (n, 4), the observation and hip kinematics, read before (progress) and written
    after the period; cfg, :func:`~.rewards.reward_config`; REW (n, 6), written: the reward
    terms and their sum (zeros for rows whose STATUS is negative: resetting, not stepped);
    FELL (n,), written: 1 where the hip fell below the fall height in this period; acfg. Rows
    with STATUS != 0 are not advanced.
    """
    if nb_check_torques(ACT, acfg) != 0:
        return 1
    _period_range(
        chs, scs, Q, QD, IST, FST, ACT, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, OBS, HIP,
        cfg, REW, FELL, 0, Q.shape[0],
    )  # fmt: skip
    return 0


@njit(cache=True, parallel=True)
def nb_env_period_parallel(
    chs, scs, Q, QD, IST, FST, ACT, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, OBS, HIP, cfg,
    REW, FELL, acfg, nt,
):  # fmt: skip
    """:func:`nb_env_period` split into ``nt`` chunks of rows, one per thread (same results)."""
    if nb_check_torques(ACT, acfg) != 0:
        return 1
    n = Q.shape[0]
    chunk = (n + nt - 1) // nt
    for c in numba.prange(nt):
        _period_range(
            chs, scs, Q, QD, IST, FST, ACT, dt, iopt, fopt, a, b, EV, FORCES, STATUS, NEV, OBS,
            HIP, cfg, REW, FELL, c * chunk, min(n, (c + 1) * chunk),
        )  # fmt: skip
    return 0


class EnvBuffers:
    """The arrays one compiled period reads and writes for N environments.

    ``sim`` (:class:`~.simulator.SimArrays`), ``act`` (n, 5) the actions [N m], ``obs``
    (n, 24), ``hip`` (n, 4: hip y, z, vy, vz), ``rew`` (n, 6: the reward terms and their sum)
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
    ):
        """Allocate for ``n`` environments of a robot, physics, period [s] and settings.

        ``cfg``: :func:`~.rewards.reward_config`; ``acfg``: :func:`~.actions.action_config`;
        ``num_threads``: numba threads that step a batch of at least ``PARALLEL_MIN_BATCH``
        rows (1: serial).
        """
        self.sim = SimArrays(n)
        self.act = np.zeros((n, N_ACTUATED))
        self.obs = np.zeros((n, OBS_DIM))
        self.hip = np.zeros((n, 4))
        self.rew = np.zeros((n, N_REWARD_OUT))
        self.fell = np.zeros(n, np.int64)
        chs, scs = params.packed
        iopt, fopt, a, b = options.packed
        s = self.sim
        self._args = (
            chs, scs, s.q, s.qd, s.ist, s.fst, self.act, float(dt), iopt, fopt, a, b, s.events,
            s.forces, s.status, s.n_events, self.obs, self.hip, cfg, self.rew, self.fell, acfg,
        )  # fmt: skip
        self.num_threads = int(num_threads)
        self._parallel = n >= PARALLEL_MIN_BATCH and self.num_threads > 1
        self._observe_args = (
            chs, scs, s.q, s.qd, s.ist, s.fst, s.forces, self.obs, self.hip, OBS_LOW, OBS_HIGH,
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
