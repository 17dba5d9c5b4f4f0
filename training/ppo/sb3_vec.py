"""Stable-Baselines3 vectorised environments for ConstrainedBiped-v0.

:func:`make_sb3_vec_env` builds the batched vector env behind :class:`BatchedSB3VecEnv` (one
compiled call steps every simulator), or SB3's own SubprocVecEnv / DummyVecEnv of single envs.
Actions are in [-1, 1] for the policy and become N m through one :class:`ActionMap`, the same
object in the single and the batched env.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecNormalize
from stable_baselines3.common.vec_env.base_vec_env import VecEnv as _SB3VecEnv

from biped_constraint_env.actions import TORQUE_LIMIT_NM


class ActionMap:
    """Policy action in [-1, 1]^5 -> joint torques [N m], optionally on top of a controller.

    Without a base: ``tau = gear * clip(a, -1, 1)``, ``gear`` [N m] per joint (a scalar or
    (5,), at most the torque limit), as Walker2d's gear. With a base controller (a callable
    ``base(obs (n, 24), residual=(n, 5))`` returning torques, e.g.
    :class:`training.controller.model_controller.ModelController`):
    ``tau = base(obs, residual=gear * a)``, a learned residual on it.
    """

    def __init__(self, gear=TORQUE_LIMIT_NM, base=None, limit: float = TORQUE_LIMIT_NM):
        """Map actions to torques (see the class docstring)."""
        g = np.broadcast_to(np.asarray(gear, dtype=np.float64), (5,)).copy()
        if not (np.all(np.isfinite(g)) and np.all(g > 0) and np.all(g <= limit)):
            raise ValueError(f"gear must be 5 values in (0, {limit}] N m, got {gear!r}")
        if base is not None and not callable(base):
            raise ValueError(f"base must be a callable controller or None, got {base!r}")
        self.gear, self.base, self.limit = g, base, float(limit)

    def __call__(self, action: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """Torques (n, 5) for actions (n, 5) and the raw observations (n, 24) they answer."""
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0) * self.gear
        if self.base is None:
            return a
        return np.clip(self.base(np.asarray(obs, np.float64), residual=a), -self.limit, self.limit)


def action_map_from(base_controller: str, gear, limit: float = TORQUE_LIMIT_NM) -> ActionMap:
    """The :class:`ActionMap` of a training config.

    ``base_controller``: "" (none: the policy's torques alone), or ``"model"`` /
    ``"model:GAINS.json"`` for :class:`training.controller.model_controller.ModelController`
    (default gains, or those overridden by the JSON file) with ``gear`` bounding the residual.
    """
    if not base_controller:
        return ActionMap(gear, None, limit)
    from training.controller.model_controller import controller_from

    return ActionMap(gear, controller_from(base_controller, limit), limit)


def make_sb3_vec_env(
    n_envs: int,
    seed: int,
    env_kwargs: dict[str, Any],
    vec: str = "batched",
    env_id: str = "ConstrainedBiped-v0",
    action_map=None,
    num_threads: int = 1,
    max_episode_steps: int | None = None,
):
    """An SB3 VecEnv of ConstrainedBiped-v0 with actions in [-1, 1] (mapped to N m).

    ``vec="batched"``: the batched vector env (all simulators in one compiled call) behind
    :class:`BatchedSB3VecEnv`; ``"subproc"``: SB3's SubprocVecEnv of single envs;
    ``"dummy"``: DummyVecEnv (one process). ``action_map``: an :class:`ActionMap` (default:
    plain rescaling by the torque limit; with PD-target actions (``action="pd"`` or a task
    that sets it, as ``task="track"``), the identity:
    the env's actions are PD targets in [-1, 1] already). ``num_threads``: numba threads of
    the batched env (1 next to a torch process on 2 cores; see the vector env).
    ``max_episode_steps``: the episodes' time limit in control periods (None: the recipes'
    :data:`~biped_constraint_env.tasks.MAX_EPISODE_STEPS`); training episodes are limited by
    periods, not by simulated time (unless ``env_kwargs`` sets ``time_limit_s``).
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    import biped_constraint_env  # noqa: F401
    from biped_constraint_env.settings import make_settings

    settings = make_settings(**env_kwargs)
    limit = settings.action.torque_limit_nm
    if settings.action.unit_actions:  # PD targets in [-1, 1] (task "track" too)
        if action_map is not None and (action_map.base is not None or action_map.limit != 1.0):
            raise ValueError("PD-target actions take ActionMap(1.0, None, 1.0): no gear, no base")
        action_map = action_map or ActionMap(1.0, None, 1.0)
    action_map = action_map or ActionMap(limit, limit=limit)
    from biped_constraint_env.tasks import MAX_EPISODE_STEPS

    limit_kw = {"max_episode_steps": max_episode_steps or MAX_EPISODE_STEPS}
    # episodes end by the training env's own limit, in periods, unless the termination sets one
    termination = {"time_limit_s": None, **(env_kwargs.get("termination") or {})}
    env_kwargs = {**env_kwargs, "termination": termination}
    if vec == "batched":
        from gymnasium.vector import AutoresetMode

        venv = gym.make_vec(
            env_id,
            num_envs=n_envs,
            vectorization_mode="vector_entry_point",
            autoreset_mode=AutoresetMode.SAME_STEP,
            num_threads=num_threads,
            info_keys=BatchedSB3VecEnv.INFO_KEYS,
            **limit_kw,
            **env_kwargs,
        )
        out = BatchedSB3VecEnv(venv, action_map)
        out.seed(seed)
        return out

    def make(i):
        def thunk():
            env = MappedAction(gym.make(env_id, **limit_kw, **env_kwargs), action_map)
            env.reset(seed=seed + i)
            return env

        return thunk

    cls = SubprocVecEnv if vec == "subproc" else DummyVecEnv
    if vec not in ("subproc", "dummy"):
        raise ValueError(f"vec must be 'batched', 'subproc' or 'dummy', got {vec!r}")
    out = cls([make(i) for i in range(n_envs)])
    out.seed(seed)
    return out


class MappedAction(gym.Wrapper):
    """A single env whose actions in [-1, 1] go through an ActionMap (which sees the raw obs)."""

    def __init__(self, env, action_map):
        """Wrap ``env``; ``action_map`` maps (actions, observations) to torques."""
        super().__init__(env)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (5,), np.float32)
        self.action_map = action_map
        self._obs = None

    def reset(self, **kwargs):
        """Reset and keep the observation for the next action."""
        obs, info = self.env.reset(**kwargs)
        self._obs = obs
        return obs, info

    def step(self, action):
        """Map the action to torques and step."""
        tau = self.action_map(np.asarray(action)[None, :], self._obs[None, :])[0]
        obs, r, term, trunc, info = self.env.step(tau)
        self._obs = obs
        return obs, r, term, trunc, info


class BatchedSB3VecEnv(_SB3VecEnv):
    """Stable-Baselines3 VecEnv over the batched ConstrainedBiped vector env (SAME_STEP resets).

    Actions arrive in [-1, 1] and become N m through ``action_map`` (default: scaled by the
    torque limit, or per joint, or a residual on a controller); a finished episode's
    last observation is ``infos[i]["terminal_observation"]`` and a time-limit end sets
    ``infos[i]["TimeLimit.truncated"]``, as SB3 expects. Each info also carries the env's
    ``steps_completed``, ``hip_y`` and ``termination_reason``.
    """

    INFO_KEYS = ("steps_completed", "hip_y", "termination_reason")
    """The env's ``info`` keys each info carries (the batched env computes only these)."""

    def __init__(self, venv, action_map=None):
        """Wrap ``venv`` (a ConstrainedBipedVectorEnv in SAME_STEP autoreset mode)."""
        from gymnasium import spaces

        self.venv = venv
        self.limit = float(venv.single_action_space.high[0])
        self.action_map = action_map or ActionMap(self.limit, limit=self.limit)
        self._obs = None
        super().__init__(
            venv.num_envs, venv.single_observation_space, spaces.Box(-1.0, 1.0, (5,), np.float32)
        )
        self._actions = None

    def reset(self):
        """Reset all sub-environments (seeded by ``seed()`` if it was called)."""
        seed = self._seeds[0]
        obs, _ = self.venv.reset(seed=seed)
        self._obs = obs
        self._reset_seeds()
        return obs.astype(np.float32)

    def step_async(self, actions):
        """Store the actions for step_wait."""
        self._actions = self.action_map(actions, self._obs)

    def step_wait(self):
        """Step the batch; returns (obs, rewards, dones, infos)."""
        obs, rew, term, trunc, info = self.venv.step(self._actions)
        self._obs = obs  # SAME_STEP: already the next episode's first observation where done
        dones = term | trunc
        cols = [info[k].tolist() for k in self.INFO_KEYS]  # Python ints, floats, names
        infos = [dict(zip(self.INFO_KEYS, row, strict=True)) for row in zip(*cols, strict=True)]
        for i in np.flatnonzero(dones).tolist():
            d, fi = infos[i], info["final_info"][i]
            d["terminal_observation"] = info["final_obs"][i].astype(np.float32)
            d["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
            d.update(steps_completed=int(fi["steps_completed"]), hip_y=float(fi["hip_y"]),
                     termination_reason=fi["termination_reason"])  # fmt: skip
        return obs.astype(np.float32), rew.astype(np.float32), dones, infos

    def close(self):
        """Close the batch."""
        self.venv.close()

    def get_attr(self, attr_name, indices=None):
        """The batch's attribute, once per requested index."""
        return [getattr(self.venv, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name, value, indices=None):
        """Set an attribute of the batch."""
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name, *args, indices=None, **kwargs):
        """Call a method of the batch, once per requested index."""
        return [
            getattr(self.venv, method_name)(*args, **kwargs) for _ in self._get_indices(indices)
        ]

    def env_is_wrapped(self, wrapper_class, indices=None):
        """The batch has no per-env Gymnasium wrappers."""
        return [False for _ in self._get_indices(indices)]


class BatchVecNormalize(VecNormalize):
    """SB3's VecNormalize whose step normalises the finished episodes' last observations at once.

    SB3 normalises each ``terminal_observation`` by its own call (a deep copy and five numpy
    calls per finished episode: most of its time early in a run, when episodes are short);
    here one call takes them all. The operations are elementwise, so every number is the same
    (``tests/test_speed_exact.py``). Statistics, settings and saving are VecNormalize's.
    """

    def step_wait(self):
        """VecNormalize.step_wait, the terminal observations normalised in one batch."""
        obs, rewards, dones, infos = self.venv.step_wait()
        self.old_obs = obs
        self.old_reward = rewards
        if self.training and self.norm_obs:
            self.obs_rms.update(obs)
        obs = self.normalize_obs(obs)
        if self.training:
            self._update_reward(rewards)
        rewards = self.normalize_reward(rewards)
        rows = [i for i in np.flatnonzero(dones).tolist() if "terminal_observation" in infos[i]]
        if rows and self.norm_obs:
            last = self._normalize_obs(
                np.stack([infos[i]["terminal_observation"] for i in rows]), self.obs_rms
            ).astype(np.float32)
            for k, i in enumerate(rows):
                infos[i]["terminal_observation"] = last[k]
        self.returns[dones] = 0
        return obs, rewards, dones, infos
