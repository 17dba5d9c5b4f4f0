"""The env core: N env rows stepped as one batch, under both the single and the vector env.

:class:`EnvCore` holds everything after the settings (:mod:`.settings`) and around the compiled
period (:mod:`.period`), written once: starts (drawn, or given by ``reset(options=...)``), the
contact clock and the tracking task, perturbations, the period itself, termination reasons,
the reward terms and ``info``. :class:`~.env.ConstrainedBipedEnv` is its N = 1 case (it adds
Gymnasium's single-env API and rendering); :class:`~.vector_env.ConstrainedBipedVectorEnv`
adds autoreset and time limits. Every row draws from its own generator (``rngs[i]``), so
row i of a batch seeded s + i is the single env seeded s + i, bit for bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .actions import action_config, action_part, validate_actions
from .clock import ContactClock
from .command import CommandReward, Commands
from .gait import GaitReward
from .model import N_ACTUATED
from .modes import EventCode
from .observation import OBSERVATION_BLOCKS, observation_names, observation_space
from .period import EnvBuffers
from .perturbations import Perturbations
from .rewards import (
    REWARD_KINDS,
    REWARD_PARTS,
    TERMINATION_FALL,
    TERMINATION_NON_FINITE,
    reward_config,
)
from .settings import EnvSettings, with_start_kind
from .simulator import SimState, evaluate
from .starts import check_start_state, draw_starts
from .state import (
    FS_DAMPED,
    FS_ROOT,
    FS_T,
    FS_WORK_ABS,
    FS_WORK_POS,
    ST_MODE,
    ST_STEPS,
    STATUS_NONFINITE,
    STATUS_TERMINATED,
)
from .terminations import terminations
from .tracking import Tracking

BASE_INFO_KEYS = ("mode", "stance_side", "steps_completed", "t", "hip_y", "root_y", "switches",
                  "events", "termination_reason", "motor_work_pos_j", "motor_work_abs_j",
                  "damping_loss_j")  # fmt: skip
"""``info`` keys of every env; the reward's terms (``reward_<term>``) follow, then, when the
settings ask for them, ``torque`` (PD actions) and ``push_impulse_ns``, ``push_dv_m_s``.
``motor_work_pos_j``, ``motor_work_abs_j``, ``damping_loss_j``: since the episode's start,
summed at every physics step, the five motors' positive and absolute work and the energy the
joint damping dissipated [J] (:data:`~.state.N_FST`)."""

NOT_STEPPED = -1
"""Status given to rows that skip a period (autoreset): the compiled period leaves them."""


EVENT_NAMES = tuple(c.name.lower() for c in sorted(EventCode))
"""Each event code's name in ``info`` (indexed by the code)."""


def event_infos(rows: list) -> tuple[tuple, tuple]:
    """``info["switches"]`` and ``info["events"]`` of one row's events.

    ``rows``: its event buffer's rows as lists (t, code, from, to, terminal), as
    :meth:`~.state.SimArrays.events_of` decodes them; ``switches``: (t, from, to) of each
    model switch; ``events``: (t, name, terminal) of each.
    """
    switches, events = [], []
    for t, code, frm, to, terminal in rows:  # one pass: a third of two generators' time
        c = int(code)
        if c == _MODE_SWITCH:
            switches.append((t, int(frm), int(to)))
        events.append((t, EVENT_NAMES[c], terminal != 0))
    return tuple(switches), tuple(events)


_MODE_SWITCH = int(EventCode.MODE_SWITCH)


def _event_rows(sim, i: int) -> list:
    """Row ``i``'s events of the last period as lists (t, code, from, to, terminal)."""
    return sim.events[i, : sim.n_events[i]].tolist()


class EnvCore:
    """N env rows with the settings ``settings`` (see the module docstring).

    Args:
        settings: :func:`~.settings.make_settings`' result. n: rows. num_threads: numba
            threads of the compiled period (1: serial; see :class:`~.period.EnvBuffers`).
    """

    def __init__(self, settings: EnvSettings, n: int, num_threads: int = 1):
        """Allocate the rows' buffers, clock, tracking task and perturbations."""
        s, p, a = settings, settings.physics, settings.action
        self.settings, self.n = s, n
        self.observation_space = observation_space(s.observation.blocks)
        self.observation_names = observation_names(s.observation.blocks)
        self.clock = ContactClock(n, p.dt) if s.needs_clock else None
        self.tracking = Tracking(n, s, self.clock) if s.needs_reference else None
        self.action_part = action_part(a, n, self.tracking)
        env_weights = (s.reward.weights if s.reward.kind == "env"
                       else tuple(t.weight for t in REWARD_KINDS["env"]))  # fmt: skip
        self.buf = EnvBuffers(
            n, p.params, p.options, p.dt,
            reward_config(env_weights, a.torque_limit_nm, s.fall_hip_height_m,
                          s.reward.kind == "env"),
            action_config(self.action_part.check_bound, a.out_of_range), num_threads,
            pcfg=self.action_part.pcfg,
        )  # fmt: skip
        self.sim, self.hip = self.buf.sim, self.buf.hip
        self.perturb = Perturbations(n, s.perturbations, p.params, self.buf)
        self.gait = GaitReward(s.reward, p.dt, n) if s.reward.kind == "gait" else None
        self.commands = None if s.command is None else Commands(n, s.command)
        self.command_reward = (CommandReward(s.reward, p.dt, n) if s.reward.kind == "command"
                               else None)  # fmt: skip
        self.reward = REWARD_PARTS[s.reward.kind]()
        self._bind_parts()
        self.reward_keys = s.reward.info_keys
        self.info_keys = (
            BASE_INFO_KEYS + self.reward_keys + tuple(k for keys, _ in self._extras for k in keys)
        )
        self._no_terms = np.zeros((n, len(self.reward_keys)))  # a reset's (never written)
        self._terms = self._no_terms
        self._reasons = np.full(n, None, dtype=object)
        self._ended_by = np.full(n, None, dtype=object)  # the learning termination of a row
        self._any_reason = False
        self._one = np.zeros(1, bool)  # the single env's terminated flag, reused
        self._posture = np.array(s.start.posture, dtype=np.float64)  # the rest posture (q)
        self._posture.flags.writeable = False

    _BOUND = ("terminations", "_before", "_after", "_blocks", "_post_obs", "_plain_obs",
              "_extras")  # fmt: skip
    """What :meth:`_bind_parts` builds: functions bound to this core's parts."""

    def _bind_parts(self) -> None:
        """The parts this env has, chosen once.

        What runs before a period, after it, in the observation and in ``info`` (the methods
        below only run the lists).
        """
        s = self.settings
        self.terminations = terminations(self)
        self._before = self._before_hooks()
        self._after = self._after_hooks()
        self._blocks = self._observation_blocks()
        self._post_obs = [self.perturb.observe] if s.perturbations.obs_noise is not None else []
        self._plain_obs = not self._blocks and not self._post_obs  # the compiled one as it is
        self._extras = self._info_extras()

    def __getstate__(self) -> dict:
        """The core's state without the functions bound to its parts (closures: rebuilt)."""
        return {k: v for k, v in self.__dict__.items() if k not in self._BOUND}

    def __setstate__(self, state: dict) -> None:
        """Restore the state, then bind the parts' functions to this core (a copy's own)."""
        self.__dict__.update(state)
        self._bind_parts()

    # ------------------------------------------------------------------ starts
    def draw_starts(self, idx: np.ndarray, rngs, command: float | np.ndarray | None = None) -> None:
        """Drawn starts of rows ``idx`` (row ``idx[k]`` from ``rngs[k]``), clocks started.

        With the reference, its reference-state starts and clock placement
        (:meth:`~.tracking.Tracking.draw_starts`); else the env's own starts.
        """
        s, st = self.settings, self.settings.start
        args = (s.physics.params, s.physics.options, self.sim, idx, rngs, st.start,
                self._posture, st.reset_noise_scale)  # fmt: skip
        if self.tracking is not None and self.tracking.ref is not None:
            self.tracking.draw_starts(*args)
        else:
            draw_starts(*args)
            if self.clock is not None:
                self.clock.start(idx, self.sim.ist[idx, ST_MODE], self.sim.qd[idx])
        self.perturb.start(idx, rngs)
        self._start_commands(idx, rngs, command)

    def _start_commands(self, idx, rngs, command: float | np.ndarray | None) -> None:
        """The rows' commands: ``command`` held (``reset(options={"command": v})``) or drawn.

        The command reward's speed averages begin again for these rows.
        """
        if self.commands is not None:
            self.commands.start(idx, rngs, self.sim.fst[idx, FS_T], command)
        elif command is not None:
            raise ValueError("reset option 'command' needs an env with a command "
                             "(task='command' or the command option)")  # fmt: skip
        if self.command_reward is not None:
            self.command_reward.start(idx)

    def set_start_kind(self, start: str | dict) -> EnvSettings:
        """Later starts of every row are drawn from ``start`` (:func:`~.settings.with_start_kind`).

        The rows running now finish their episodes; returns the new settings.
        """
        self.settings = with_start_kind(self.settings, start)
        return self.settings

    def set_starts(
        self, idx: np.ndarray, state: SimState, rngs, command: float | np.ndarray | None = None
    ) -> None:
        """Rows ``idx`` start at the given (checked) ``state`` (``reset(options=...)``)."""
        p = self.settings.physics
        check_start_state(p.params, state)
        forces = evaluate(p.params, state, np.zeros(N_ACTUATED), p.options)[1]
        for i in idx:
            self.sim.set(int(i), state, forces)
        if self.clock is not None:
            if self.tracking is not None and self.tracking.ref is not None:
                self.tracking.start_given(idx, self.sim)
            else:
                self.clock.start(idx, self.sim.ist[idx, ST_MODE], self.sim.qd[idx])
        self.perturb.start(idx, rngs)
        self._start_commands(idx, rngs, command)

    # ------------------------------------------------------------------ the period
    def period(self, actions: np.ndarray, rngs, skip: np.ndarray | None = None):
        """One control period of every row but ``skip``; (rewards (n,), terminated (n,)).

        ``actions`` (n, 5) float: checked (NaN, inf, the bound) and clipped in the compiled
        period, which refuses through :func:`~.actions.validate_actions`' ``ValueError``.
        Afterwards :meth:`info` gives the period's ``info``.
        """
        actions = self._before_period(actions, rngs, skip)
        snap = self.reward.before(self)
        self._run(actions, skip)
        terminated = self._terminated(skip)
        self._terms, rewards = self.reward.after(self, snap, terminated, skip)
        self._set_reasons(terminated)
        return rewards, terminated

    # ------------------------------------------------------------------ the parts' hooks
    def _rows(self, skip) -> range | np.ndarray:
        """The rows a period steps (all but ``skip``)."""
        return range(self.n) if skip is None else np.setdiff1d(np.arange(self.n), skip)

    def _before_hooks(self) -> list:
        """What runs before a period, in order: fn(actions, rngs, rows) -> actions.

        ``rows``: the rows the period steps (all but the skipped ones), found once per period.
        """
        sim = self.sim
        hooks = self.action_part.hooks(self.buf, lambda: sim.ist[:, ST_MODE])

        def perturb(actions, rngs, rows):  # pushes due now (stepped rows); delayed actions
            return self.perturb.before_period(actions.astype(np.float64), rngs, rows)

        def commands(actions, rngs, rows):  # commands due for resampling
            self.commands.before_period(sim.fst[:, FS_T], rngs, rows)
            return actions

        if self.perturb.active:
            hooks.append(perturb)
        if self.commands is not None:
            hooks.append(commands)
        return hooks

    def _after_hooks(self) -> list:
        """What runs after the compiled period, in order: fn(stepped) (None: every row)."""
        hooks, sim = [], self.sim
        if self.clock is not None:
            hooks.append(
                lambda stepped: self.clock.advance(
                    sim.ist[:, ST_MODE], sim.ist[:, ST_STEPS], stepped
                )
            )
            if self.tracking is not None:
                hooks.append(lambda stepped: self.tracking.after_period(sim.ist[:, ST_STEPS]))
        return hooks  # fmt: skip

    def _observation_blocks(self) -> list:
        """The observation's blocks after the base entries: fn() -> (n, k), in order."""
        blocks = [OBSERVATION_BLOCKS[b].features for b in self.settings.observation.blocks]
        return [lambda f=f: f(self) for f in blocks]

    def _info_extras(self) -> list:
        """``info`` entries of the parts: (keys, fn(row) -> values), in order."""
        extras = []
        part = self.action_part
        if part.info_keys:  # the period's time-mean PD torque
            extras.append((part.info_keys, lambda row: part.info(self.buf, row)))
        if self.settings.perturbations.push_impulse_ns is not None:
            p = self.perturb
            extras.append(
                (
                    ("push_impulse_ns", "push_dv_m_s"),
                    lambda row: (
                        (p.push_ns.item(row), p.push_dv.item(row))
                        if row is not None
                        else (p.push_ns.copy(), p.push_dv.copy())
                    ),
                )
            )
        if self.commands is not None:  # the command the next period runs under
            c = self.commands
            extras.append(
                (("command_m_s",), lambda row: (c.v.item(row) if row is not None else c.v.copy(),))
            )
        return extras  # fmt: skip

    # ------------------------------------------------------------------ the period, in steps
    def _before_period(self, actions: np.ndarray, rngs, skip) -> np.ndarray:
        """The parts' hooks before the period (PD bases, pushes, delays, commands)."""
        rows = self._rows(skip) if self._before else None
        for hook in self._before:
            actions = hook(actions, rngs, rows)
        self.buf.act[:] = actions
        return actions

    def _run(self, actions: np.ndarray, skip) -> None:
        """The compiled period of every row but ``skip``, then the contact clock."""
        buf, sim = self.buf, self.sim
        if skip is not None:
            sim.status[skip] = NOT_STEPPED
        if buf.period():  # refused: the check of what ``act`` holds raises its ValueError
            part = self.action_part
            validate_actions(actions, part.check_bound, self.settings.action.out_of_range,
                             part.bound_name)  # fmt: skip
            raise AssertionError(f"the compiled action check refused {actions}, Python not")
        stepped = None
        if skip is not None:
            sim.status[skip] = 0
            sim.n_events[skip] = 0
            stepped = np.ones(self.n, bool)
            stepped[skip] = False
        for hook in self._after:
            hook(stepped)

    def _terminated(self, skip) -> np.ndarray:
        """The rows the period ended: an out-of-model event or a fall, then :attr:`terminations`."""
        sim, buf = self.sim, self.buf
        if self.n == 1:  # the single env: scalar reads, a fifth of its step's Python time
            terminated = self._one
            terminated[0] = sim.status.item(0) > 0 or buf.fell.item(0) != 0
        else:
            terminated = (sim.status > 0) | (buf.fell != 0)
        for ends in self.terminations:  # the learning task's, in order; the first names a row
            hit = ends(skip)
            new = hit & ~terminated
            if new.any():
                self._ended_by[new] = ends.reason
            terminated |= hit
        return terminated

    def _set_reasons(self, terminated: np.ndarray) -> None:
        """The termination reason of every row (None where it goes on)."""
        reasons, sim = self._reasons, self.sim
        if self._any_reason:  # the last period named some: forget them
            reasons[:] = None
        self._any_reason = bool(terminated[0] if self.n == 1 else terminated.any())
        if not self._any_reason:
            return
        for i in (0,) if self.n == 1 else np.flatnonzero(terminated).tolist():
            status = sim.status.item(i)
            if status == STATUS_TERMINATED:  # the terminal event names it
                ev = sim.events[i]
                k = next(k for k in range(sim.n_events.item(i)) if ev.item(k, 4))
                reasons[i] = EVENT_NAMES[int(ev.item(k, 1))]
            elif status == STATUS_NONFINITE:
                reasons[i] = TERMINATION_NON_FINITE
            elif self.buf.fell.item(i):
                reasons[i] = TERMINATION_FALL
            else:  # a learning termination
                reasons[i], self._ended_by[i] = self._ended_by[i], None

    def clear_period(self) -> None:
        """Forget the last period (after a reset: no events, zero terms, no reasons)."""
        self.sim.n_events[:] = 0
        self._terms = self._no_terms
        if self._any_reason:
            self._reasons[:] = None
            self._any_reason = False
        if self.perturb.active:  # only pushes write them
            self.perturb.push_ns[:] = 0.0
            self.perturb.push_dv[:] = 0.0
        self.action_part.clear(self.buf)

    # ------------------------------------------------------------------ observation, info
    def observation(self, rngs, rows=None) -> np.ndarray:
        """(n, dim) observations, a fresh array.

        The base entries, the phase and reference entries (when asked for), sensor noise on
        ``rows`` (default all).
        """
        obs = self.buf.obs
        if self._blocks:
            obs = np.concatenate([obs, *(block() for block in self._blocks)], axis=1)
        for post in self._post_obs:  # sensor noise
            obs = post(obs, rngs, range(self.n) if rows is None else rows)
        return obs.copy() if obs is self.buf.obs else obs

    def first_observation(self, rngs) -> np.ndarray:
        """Row 0's observation (the single env's), a fresh (dim,) array."""
        if self._plain_obs:
            return self.buf.obs[0].copy()
        return self.observation(rngs)[0]

    def info(self, row: int | None = None, keys: tuple | None = None) -> dict[str, Any]:
        """The last period's (or reset's) ``info``.

        ``row`` None: one array per key (entry i: env i), as the vector env gives it; a row
        index: that row's values as Python scalars and tuples, as the single env gives them.
        ``keys`` (with ``row`` None): only these keys (a subset of :attr:`info_keys`, checked
        by the caller), the events decoded only if asked for.
        """
        sim, one = self.sim, row is not None
        if one:
            mode, side, steps, _ = sim.ist[row].tolist()
            f = sim.fst[row].tolist()
            switches, events = event_infos(_event_rows(sim, row)) if sim.n_events.item(row) \
                else ((), ())  # fmt: skip
            out = {"mode": mode, "stance_side": side, "steps_completed": steps,
                   "t": f[FS_T], "hip_y": self.hip.item(row, 0), "root_y": f[FS_ROOT],
                   "switches": switches, "events": events,
                   "termination_reason": self._reasons.item(row),
                   "motor_work_pos_j": f[FS_WORK_POS], "motor_work_abs_j": f[FS_WORK_ABS],
                   "damping_loss_j": f[FS_DAMPED]}  # fmt: skip
            for key, value in zip(self.reward_keys, self._terms[row].tolist(), strict=True):
                out[key] = value  # (a third faster than dict.update here)
        else:
            switches = np.empty(self.n, dtype=object)
            events = np.empty(self.n, dtype=object)
            switches[:] = [()] * self.n
            events[:] = [()] * self.n
            if keys is None or "switches" in keys or "events" in keys:
                for i in np.flatnonzero(sim.n_events[: self.n]):
                    switches[i], events[i] = event_infos(_event_rows(sim, i))
            mode, side, steps = sim.ist[:, :3].T.copy()  # ST_MODE, ST_SIDE, ST_STEPS: 0, 1, 2
            out = {"mode": mode, "stance_side": side, "steps_completed": steps,
                   "t": sim.fst[:, FS_T].copy(), "hip_y": self.hip[:, 0].copy(),
                   "root_y": sim.fst[:, FS_ROOT].copy(),
                   "switches": switches, "events": events,
                   "termination_reason": self._reasons.copy(),
                   "motor_work_pos_j": sim.fst[:, FS_WORK_POS].copy(),
                   "motor_work_abs_j": sim.fst[:, FS_WORK_ABS].copy(),
                   "damping_loss_j": sim.fst[:, FS_DAMPED].copy()}  # fmt: skip
            out.update(zip(self.reward_keys, self._terms.T.copy(), strict=True))
        for names, values in self._extras:
            out.update(zip(names, values(row), strict=True))
        return out if keys is None else {k: out[k] for k in keys}
