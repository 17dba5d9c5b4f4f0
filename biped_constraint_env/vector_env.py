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
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .actions import validate_actions
from .command import check_commands, split_reset_options
from .core import EnvCore
from .model import N_ACTUATED
from .settings import make_settings
from .starts import state_from_options
from .state import FS_T
from .validation import check_int, check_seeds

MAX_NUM_ENVS = 1_000_000
"""Largest accepted ``num_envs``."""


class ConstrainedBipedVectorEnv(VectorEnv):
    """N ConstrainedBiped-v0 environments in one batch (arguments as the single env).

    Args:
        num_envs: number of sub-environments.
        max_episode_steps: truncation after this many control periods (None, the default:
            none; the env's ``time_limit_s`` truncates by simulated time).
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (Gymnasium's default) or ``SAME_STEP``
            (a finished sub-environment is reset within the same step; its last observation
            is in ``info["final_obs"]`` and its last info in ``info["final_info"]``, as
            Stable-Baselines3's VecEnv expects).
        num_threads: numba threads of the compiled period (1: serial).
        info_keys: the ``info`` keys each reset and step returns (None, the default: every
            key, ``core.info_keys``); a learner that reads a few asks for those alone, and the
            others (the events' decoding above all) are not computed.
        **kwargs: the single environment's keyword arguments (``render_mode`` excepted),
            validated once into ``settings`` (:mod:`.settings`).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        num_threads: int = 1,
        info_keys: tuple[str, ...] | None = None,
        **kwargs: Any,
    ):
        """Create the batch."""
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
        self.settings = make_settings(**kwargs)
        s = self.settings
        self.core = EnvCore(s, num_envs, num_threads)
        if info_keys is not None:
            if isinstance(info_keys, str) or not all(isinstance(k, str) for k in info_keys):
                raise ValueError(f"info_keys must be a sequence of key names, got {info_keys!r}")
            unknown = [k for k in info_keys if k not in self.core.info_keys]
            if unknown:
                raise ValueError(f"info_keys {unknown} are not keys of this env's info "
                                 f"{self.core.info_keys}")  # fmt: skip
            info_keys = tuple(dict.fromkeys(info_keys))
        self.info_keys = info_keys
        self.num_envs = num_envs
        self.num_threads = num_threads
        self.max_episode_steps = max_episode_steps
        bound = s.action.bound
        self.single_action_space = spaces.Box(-bound, bound, (N_ACTUATED,), np.float32)
        self.single_observation_space = self.core.observation_space
        self.observation_names = self.core.observation_names  # entry names, in order
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.params, self.options, self.dt = s.physics.params, s.physics.options, s.dt
        self._needs_reset = True  # until the first reset succeeds
        self._elapsed = np.zeros(num_envs, np.int64)
        self._autoreset = np.zeros(num_envs, bool)
        self._all = np.arange(num_envs)
        self._everyone = np.ones(num_envs, bool)
        self._rngs: list[np.random.Generator] = [
            seeding.np_random(None)[0] for _ in range(num_envs)
        ]

    def __repr__(self) -> str:
        """The batch with its settings."""
        return f"ConstrainedBipedVectorEnv(num_envs={self.num_envs}, {self.settings!r})"

    def _reset_rows(self, idx: np.ndarray, command: float | np.ndarray | None = None) -> None:
        """Drawn starts for rows ``idx`` (each from its own generator, as the single env)."""
        self.core.draw_starts(idx, [self._rngs[i] for i in idx], command)
        self._elapsed[idx] = 0

    def set_start(self, start: str | dict) -> None:
        """Every row's next starts from ``start``, as :meth:`.ConstrainedBipedEnv.set_start`."""
        self.settings = self.core.set_start_kind(start)

    def set_command(self, values) -> np.ndarray:
        """Set the commanded forward speeds [m/s]: one value for all rows or one per row.

        They hold until each row's next reset (an automatic reset draws a new command);
        the next observation carries them. Returns the held commands (num_envs,): 0 where a
        value is inside the command's deadband. ValueError without a command
        (``task="command"``).
        """
        if self.core.commands is None:
            raise ValueError("set_command needs an env with a command (task='command')")
        return self.core.commands.set(check_commands(values, self.num_envs, "set_command"))

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset every sub-environment; ``seed`` s seeds sub-environment i with s + i."""
        self._needs_reset = True  # stays so if this reset is refused
        if seed is not None:
            seeds = check_seeds(seed, self.num_envs)
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        options, command = split_reset_options(options, self.num_envs)
        if options is not None and not (isinstance(options, dict) and not options):
            self.core.set_starts(self._all, state_from_options(options), self._rngs, command)
            self._elapsed[:] = 0
        else:
            self._reset_rows(self._all, command)
        self._autoreset[:] = False
        self.core.buf.observe()
        self.core.clear_period()
        self._needs_reset = False
        return self.core.observation(self._rngs), self._masked(self.core.info(keys=self.info_keys))

    def step(self, actions):
        """Step every sub-environment (autoreset as ``autoreset_mode`` says)."""
        if self._needs_reset:
            raise RuntimeError("step() called before reset(); call reset()")
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs, N_ACTUATED):
            raise ValueError(
                f"actions must have shape ({self.num_envs}, {N_ACTUATED}), got {actions.shape}"
            )
        a = self.settings.action
        act = validate_actions(actions, a.bound, a.out_of_range, a.bound_name)
        resetting = np.flatnonzero(self._autoreset)
        if resetting.size:  # NEXT_STEP: these rows start again and skip the period
            self._reset_rows(resetting)
        skip = resetting if resetting.size else None
        rewards, terminated = self.core.period(act, self._rngs, skip)
        rewards = rewards.copy()  # the core's may be a view the next period overwrites
        self._elapsed += 1
        self._elapsed[resetting] = 0
        infos = self.core.info(keys=self.info_keys)
        truncated = np.zeros(self.num_envs, bool)
        if self.max_episode_steps is not None:
            truncated = (self._elapsed >= self.max_episode_steps) & ~terminated
        limit = self.settings.time_limit_s
        if limit is not None:
            truncated |= (self.core.sim.fst[:, FS_T] >= limit - 1e-9) & ~terminated
        done = np.flatnonzero(terminated | truncated)
        obs = self.core.observation(self._rngs)
        if self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP and done.size:
            final_obs = np.full(self.num_envs, None, dtype=object)
            final_info = np.full(self.num_envs, None, dtype=object)
            for i in done:
                final_obs[i] = obs[i].copy()
                final_info[i] = {k: v[i] for k, v in infos.items()}
            self._reset_rows(done)
            self.core.buf.observe()
            obs[done] = self.core.observation(self._rngs, rows=done)[done]
            mask = np.zeros(self.num_envs, bool)
            mask[done] = True
            infos = self._masked(infos)
            infos.update(
                final_obs=final_obs, _final_obs=mask, final_info=final_info, _final_info=mask
            )
            return obs, rewards, terminated, truncated, infos
        self._autoreset = terminated | truncated
        return obs, rewards, terminated, truncated, self._masked(infos)

    def _masked(self, info: dict[str, Any]) -> dict[str, Any]:
        """``info`` with Gymnasium's per-key masks (every entry is set for every env)."""
        info.update({f"_{k}": self._everyone for k in list(info)})
        return info

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release."""
