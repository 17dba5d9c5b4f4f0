"""Exploration at a zero command: a small, fixed noise where the command task asks to stand.

A joint PD law holds the standing start for 8 s under 0.3 N m of Gaussian torque noise per
joint in 19 of 20 episodes, under 1 N m in 12 of 20 and under 3 N m in none
(``results/command_stage4/README.md``); PPO's exploration noise on a walker is 1-5 N m. So with
one noise for every state, no standing episode lasts long enough for PPO to sample standing
still. ``PPOConfig.stand_std_nm`` > 0 gives the rows whose commanded speed is zero their own
fixed noise (that std in N m at every joint); the other rows keep the policy's learned std.

Two parts, both for training only (the published network is a plain ``MlpPolicy``: its
deterministic action is the mean, which this does not touch):

* :class:`PinnedStats`: VecNormalize's observation statistics with the command entry held at
  mean 0 and variance 1, so that the network reads the command in m/s and a zero command is an
  exact 0 in the normalised observation (the saved normaliser says so, and the run-time actor
  computes the same input).
* :class:`StandNoisePolicy`: SB3's ``ActorCriticPolicy`` whose Gaussian has, row by row, the
  fixed log-std ``stand_log_std`` where the command entry is 0. Rollout and update compute the
  same distribution from the same stored observation, so PPO's ratio stays exact.
"""

from __future__ import annotations

import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.running_mean_std import RunningMeanStd


def _pinned(v, index: int, value: float) -> np.ndarray:
    v = np.array(v, dtype=np.float64)  # a copy: never the caller's array
    v[index] = value
    return v


class PinnedStats(RunningMeanStd):
    """Running mean and variance with one entry held at mean 0 and variance 1 (the identity).

    Every assignment to ``mean`` or ``var`` (SB3's update, a restored snapshot) is pinned.
    """

    def __init__(self, shape: tuple[int, ...], index: int):
        """``index``: the entry held (negative counts from the end)."""
        self._index = index
        super().__init__(shape=shape)

    @property
    def mean(self) -> np.ndarray:
        """The running mean (the pinned entry 0)."""
        return self._mean

    @mean.setter
    def mean(self, v) -> None:
        self._mean = _pinned(v, self._index, 0.0)

    @property
    def var(self) -> np.ndarray:
        """The running variance (the pinned entry 1)."""
        return self._var

    @var.setter
    def var(self, v) -> None:
        self._var = _pinned(v, self._index, 1.0)


def pin_command(vecnorm, index: int = -1) -> None:
    """Hold the command entry of ``vecnorm``'s observation statistics at the identity."""
    old = vecnorm.obs_rms
    stats = PinnedStats(old.mean.shape, index)
    stats.mean, stats.var, stats.count = old.mean, old.var, old.count
    vecnorm.obs_rms = stats


class StandNoisePolicy(ActorCriticPolicy):
    """``ActorCriticPolicy`` with a fixed exploration noise on rows commanded to stand.

    ``stand_log_std``: the log-std (action units, one per action) where the command entry
    (``command_index`` of the normalised observation, pinned to the identity by
    :func:`pin_command`) is exactly 0; elsewhere the policy's own learned ``log_std``. The
    weights and their names are ``ActorCriticPolicy``'s (the log-std at a zero command is a
    setting, not a weight).
    """

    def __init__(self, *args, stand_log_std=(), command_index: int = -1, **kwargs):
        super().__init__(*args, **kwargs)
        if self.use_sde:
            raise ValueError("stand_std_nm does not combine with use_sde")
        stand = torch.as_tensor(np.asarray(stand_log_std, np.float32))
        if stand.shape != (self.action_space.shape[0],):
            raise ValueError(f"stand_log_std needs {self.action_space.shape[0]} values, "
                             f"got {tuple(stand.shape)}")  # fmt: skip
        self.register_buffer("stand_log_std", stand, persistent=False)
        self.command_index = command_index
        self._stand: torch.Tensor | None = None

    def _with_stand(self, obs, fn):
        self._stand = obs[..., self.command_index] == 0
        try:
            return fn()
        finally:
            self._stand = None

    def forward(self, obs, deterministic: bool = False):
        """SB3's rollout pass (actions, values, log-probabilities), with the rows' noise."""
        parent = super()
        return self._with_stand(obs, lambda: parent.forward(obs, deterministic))

    def evaluate_actions(self, obs, actions):
        """SB3's update pass (values, log-probabilities, entropy), with the rows' noise."""
        parent = super()
        return self._with_stand(obs, lambda: parent.evaluate_actions(obs, actions))

    def get_distribution(self, obs):
        """The action distribution of ``obs``, with the rows' noise."""
        parent = super()
        return self._with_stand(obs, lambda: parent.get_distribution(obs))

    def _get_action_dist_from_latent(self, latent_pi):
        if self._stand is None:  # every public route sets the rows first
            raise RuntimeError("StandNoisePolicy: the distribution needs the observation")
        mean = self.action_net(latent_pi)
        log_std = torch.where(self._stand[:, None], self.stand_log_std, self.log_std)
        return self.action_dist.proba_distribution(mean, log_std)


def fold_command_input(policy, mean: float, var: float, eps: float) -> None:
    """Make a network that read the command normalised read it in m/s, exactly (in place).

    Its first layers (actor and critic) saw ``(c - mean) / sqrt(var + eps)``; with the weights
    of that input divided by the scale and the bias moved by ``-w mean / scale``, they compute
    the same from ``c`` itself. Exact where the old input was not clipped (the caller checks).
    """
    scale = float(np.sqrt(var + eps))
    for net in (policy.mlp_extractor.policy_net, policy.mlp_extractor.value_net):
        first = net[0] if len(net) else None
        if not isinstance(first, torch.nn.Linear):
            raise ValueError("the network has no first linear layer to take the command")
        with torch.no_grad():
            w = first.weight[:, -1].clone()
            first.weight[:, -1] = w / scale
            first.bias -= w * (mean / scale)
