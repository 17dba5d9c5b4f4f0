"""Batched vector environment: N simulators stepped by one compiled call.

``gym.make_vec("ConstrainedBiped-v0", num_envs=N, vectorization_mode="vector_entry_point")``
creates it. It uses the same compiled simulator step, the same observation, reward, start-state
and validation functions as :class:`~biped_constraint_env.env.ConstrainedBipedEnv`, so its
trajectories equal those of N single environments seeded ``seed + i`` (Gymnasium's
``SyncVectorEnv`` convention). Autoreset follows Gymnasium's ``NEXT_STEP`` mode: the step
after an episode ends resets that sub-environment and ignores its action.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .actions import action_config, validate_actions
from .env import (
    TRACK_KEYS,
    ConstrainedBipedEnv,
    draw_episode_starts,
    event_infos,
    make_clock_and_tracking,
    observations,
    start_clocks,
)
from .model import N_ACTUATED
from .period import EnvBuffers
from .perturbations import Perturbations
from .rewards import REWARD_TERMS, TERMINATION_FALL, TERMINATION_NON_FINITE, reward_config
from .simulator import evaluate
from .starts import check_start_state, state_from_options
from .state import STATUS_NONFINITE
from .tasks import MAX_EPISODE_STEPS
from .validation import check_int, check_seeds

MAX_NUM_ENVS = 1_000_000
"""Largest accepted ``num_envs``."""

_MASK_KEYS = tuple(
    f"_{k}"
    for k in (
        "mode",
        "stance_side",
        "steps_completed",
        "t",
        "hip_y",
        "switches",
        "events",
        "termination_reason",
    )  # fmt: skip
    + REWARD_TERMS
)
"""Gymnasium's per-key masks of the vector info (every entry is set for every env)."""


class ConstrainedBipedVectorEnv(VectorEnv):
    """N ConstrainedBiped-v0 environments in one batch (arguments as the single env).

    Args:
        num_envs: number of sub-environments.
        max_episode_steps: truncation after this many control periods (registration: 6000;
            None: never).
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (Gymnasium's default) or ``SAME_STEP``
            (a finished sub-environment is reset within the same step; its last observation
            is in ``info["final_obs"]`` and its last info in ``info["final_info"]``, as
            Stable-Baselines3's VecEnv expects).
        **kwargs: the single environment's keyword arguments (``render_mode`` excepted).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = MAX_EPISODE_STEPS,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        num_threads: int = 1,
        **kwargs: Any,
    ):
        """Create the batch; the single env validates the arguments."""
        if kwargs.get("render_mode") is not None:
            raise ValueError("the batched vector env does not render; use gym.make for that")
        kwargs.pop("render_mode", None)
        num_envs = check_int("num_envs", num_envs, 1, MAX_NUM_ENVS)
        if max_episode_steps is not None:
            max_episode_steps = check_int("max_episode_steps", max_episode_steps, 1, 2**62)
        num_threads = check_int("num_threads", num_threads, 1, numba.config.NUMBA_NUM_THREADS)
        try:
            autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(
                f"autoreset_mode must be NEXT_STEP or SAME_STEP, got {autoreset_mode!r}"
            ) from None
        if autoreset_mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode must be NEXT_STEP or SAME_STEP, got {autoreset_mode}")
        self.metadata = {**self.metadata, "autoreset_mode": autoreset_mode}
        self._proto = ConstrainedBipedEnv(**kwargs)  # validation and settings, never stepped
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.single_action_space = self._proto.action_space
        self.single_observation_space = self._proto.observation_space
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.params = self._proto.params
        self.options = self._proto.options
        self.dt = self._proto.dt
        p = self._proto
        self._buf = EnvBuffers(
            num_envs,
            self.params,
            self.options,
            self.dt,
            reward_config(p.weights, p.torque_limit_nm, p.fall_hip_height_m),
            action_config(p.action_bound, p.out_of_range),
            num_threads,
            pcfg=p.action_mapping(),
        )
        self.num_threads = num_threads
        self._sim, self._obs, self._hip = self._buf.sim, self._buf.obs, self._buf.hip
        self._needs_reset = True  # until the first reset succeeds
        self._clock, self.tracking = make_clock_and_tracking(num_envs, p)
        self._perturb = Perturbations(num_envs, p.perturbation_settings, p.params, self._buf)
        self._track_reward = p.tracking_settings["reward"] == "tracking"
        self._pd = p.pd_action
        self._elapsed = np.zeros(num_envs, np.int64)
        self._autoreset = np.zeros(num_envs, bool)
        self._rngs: list[np.random.Generator] = [
            seeding.np_random(None)[0] for _ in range(num_envs)
        ]

    def _reset_slots(self, idx: np.ndarray) -> None:
        """Sampled starts for slots ``idx`` (each drawn from its own RNG, as the single env)."""
        rngs = [self._rngs[i] for i in idx]
        draw_episode_starts(self._proto, self._sim, idx, rngs, self._clock, self.tracking)
        self._perturb.start(idx, rngs)
        self._elapsed[idx] = 0

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset every sub-environment; ``seed`` s seeds sub-environment i with s + i."""
        self._needs_reset = True  # stays so if this reset is refused
        if seed is not None:
            seeds = check_seeds(seed, self.num_envs)
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        if options is not None and not (isinstance(options, dict) and not options):
            state = state_from_options(options)
            check_start_state(self.params, state)
            for i in range(self.num_envs):
                self._sim.set(
                    i, state, evaluate(self.params, state, np.zeros(N_ACTUATED), self.options)[1]
                )
            self._elapsed[:] = 0
            start_clocks(self._clock, self.tracking, np.arange(self.num_envs), self._sim)
            self._perturb.start(np.arange(self.num_envs), self._rngs)
        else:
            self._reset_slots(np.arange(self.num_envs))
        self._autoreset[:] = False
        self._fell = np.zeros(self.num_envs, bool)
        self._observe()
        self._needs_reset = False
        return self._observation(), self._infos(np.zeros(self.num_envs), None)

    def step(self, actions):
        """Step every sub-environment (autoreset on the step after an episode ends)."""
        if self._needs_reset:
            raise RuntimeError("step() called before reset(); call reset()")
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs, N_ACTUATED):
            raise ValueError(
                f"actions must have shape ({self.num_envs}, {N_ACTUATED}), got {actions.shape}"
            )
        p = self._proto
        buf = self._buf
        act = validate_actions(actions, p.action_bound, p.out_of_range, p.action_bound_name)
        resetting = np.flatnonzero(self._autoreset)
        if resetting.size:
            self._reset_slots(resetting)
        if self._pd:  # after the resets: the targets' bases at the clocks of the new starts
            buf.tgt[:], buf.rate[:] = self.tracking.bases(self.num_envs)
        if self._perturb.active:  # pushes due now (stepped rows); the delayed actions
            stepped_rows = np.flatnonzero(~self._autoreset)
            act = self._perturb.before_period(act, self._rngs, stepped_rows)
        buf.act[:] = act
        steps0 = buf.sim.ist[:, 2].copy()
        buf.sim.status[resetting] = -1  # not stepped this period; zero reward
        if buf.period():  # the actions were validated above, so this cannot fail
            raise AssertionError(f"the compiled action check refused validated actions {act}")
        buf.sim.status[resetting] = 0
        buf.sim.n_events[resetting] = 0
        if self._clock is not None:
            stepped = np.ones(self.num_envs, bool)
            stepped[resetting] = False
            self._clock.advance(buf.sim.ist[:, 0], buf.sim.ist[:, 2], stepped)
            if self.tracking is not None:
                self.tracking.after_period(buf.sim.ist[:, 2])
        status = buf.sim.status
        fell = buf.fell.astype(bool)
        terminated = (status > 0) | fell
        self._fell = fell
        parts = tuple(buf.rew[:, : len(REWARD_TERMS)].T.copy())  # one copy, a row per term
        rewards = buf.rew[:, -1].copy()
        if self._track_reward:
            track = self.tracking.reward(
                buf.sim.q, buf.sim.qd, self._hip, buf.sim.ist[:, 2] - steps0, ~terminated
            )
            track[resetting] = 0.0  # not stepped this period
            parts = parts + tuple(track[:, :-1].T.copy())
            rewards = track[:, -1].copy()
        self._elapsed += 1
        self._elapsed[resetting] = 0
        truncated = np.zeros(self.num_envs, bool)
        if self.max_episode_steps is not None:
            truncated = (self._elapsed >= self.max_episode_steps) & ~terminated
        infos = self._infos(np.zeros(self.num_envs), parts)
        if self._pd:  # the time-mean PD torque of the period
            infos.update(torque=buf.act.copy(), _torque=np.ones(self.num_envs, bool))
        if self._perturb.s.push_impulse_ns is not None:
            everyone = np.ones(self.num_envs, bool)
            infos.update(
                push_impulse_ns=self._perturb.push_ns.copy(), _push_impulse_ns=everyone,
                push_dv_m_s=self._perturb.push_dv.copy(), _push_dv_m_s=everyone,
            )  # fmt: skip
        done = np.flatnonzero(terminated | truncated)
        obs = self._observation()
        if self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP and done.size:
            final_obs = np.full(self.num_envs, None, dtype=object)
            final_info = np.full(self.num_envs, None, dtype=object)
            keys = [k for k in infos if not k.startswith("_")]
            for i in done:
                final_obs[i] = obs[i].copy()
                final_info[i] = {k: infos[k][i] for k in keys}
            self._reset_slots(done)
            self._observe()
            obs[done] = self._observation(rows=done)[done]
            mask = np.zeros(self.num_envs, bool)
            mask[done] = True
            infos.update(
                final_obs=final_obs, _final_obs=mask, final_info=final_info, _final_info=mask
            )
        else:
            self._autoreset = terminated | truncated
        return obs, rewards, terminated, truncated, infos

    def _observation(self, rows=None) -> np.ndarray:
        """The observations (phase and reference entries, and noise on ``rows``: all)."""
        obs = (
            self._obs
            if self._clock is None
            else observations(self._obs, self._clock, self.tracking, self._proto)
        )
        rows = range(self.num_envs) if rows is None else rows
        out = self._perturb.observe(obs, self._rngs, rows)
        return out.copy() if out is self._obs else out

    def _observe(self) -> None:
        self._buf.observe()

    def _infos(self, zeros: np.ndarray, terms) -> dict[str, Any]:
        s = self._sim
        reasons = np.full(self.num_envs, None, dtype=object)
        fell = getattr(self, "_fell", None)
        if fell is not None and fell.any():
            reasons[fell] = TERMINATION_FALL
        for i in np.flatnonzero(s.status > 0):
            if s.status[i] == STATUS_NONFINITE:
                reasons[i] = TERMINATION_NON_FINITE
            else:
                reasons[i] = next(e.code.name.lower() for e in s.events_of(int(i)) if e.terminal)
        keys = REWARD_TERMS + (TRACK_KEYS if self._track_reward else ())
        parts = terms if terms is not None else (zeros,) * len(keys)
        mode, side, steps = s.ist[:, :3].T.copy()  # one copy, a row per entry
        switches, events = _event_infos(s, self.num_envs)
        info = {
            "mode": mode,
            "stance_side": side,
            "steps_completed": steps,
            "t": s.fst[:, 0].copy(),
            "hip_y": self._hip[:, 0].copy(),
            "switches": switches,
            "events": events,
            "termination_reason": reasons,
            **dict(zip(keys, parts, strict=True)),
        }
        everyone = np.ones(self.num_envs, bool)
        info.update(dict.fromkeys(_MASK_KEYS, everyone))
        if self._track_reward:
            info.update(dict.fromkeys((f"_{k}" for k in TRACK_KEYS), everyone))
        return info

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release."""


def _event_infos(sim, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per row, the single env's ``info["switches"]`` and ``info["events"]`` (object arrays)."""
    switches = np.empty(n, dtype=object)
    events = np.empty(n, dtype=object)
    switches[:] = [()] * n
    events[:] = [()] * n
    for i in np.flatnonzero(sim.n_events[:n]):
        sw, ev = event_infos(sim.events_of(int(i)))
        switches[i], events[i] = sw, ev
    return switches, events
