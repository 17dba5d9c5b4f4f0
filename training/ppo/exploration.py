"""Exploration at a zero command: a small, fixed noise where the command task asks to stand.

A joint PD law holds the standing start for 8 s under 0.3 N m of Gaussian torque noise per
joint in 19 of 20 episodes, under 1 N m in 12 of 20 and under 3 N m in none
(``results/command_stage4/README.md``); PPO's exploration noise on a walker is 1-5 N m. So with
one noise for every state, no standing episode lasts long enough for PPO to sample standing
still. ``PPOConfig.stand_std_nm`` > 0 gives the rows whose commanded speed is zero (and, with
``stand_speed_m_s`` > 0, whose hip moves forward or back slower than that) their own fixed
noise (that std in N m at every joint); the other rows keep the policy's learned std.

Two parts, both for training only (the published network is a plain ``MlpPolicy``: its
deterministic action is the mean, which this does not touch):

* :class:`PinnedStats`: VecNormalize's observation statistics with the command and the hip's
  forward speed (:data:`PINNED`) held at mean 0 and variance 1, so that the network reads both
  in m/s and the rows are told apart exactly in the normalised observation (the saved
  normaliser says so, and the run-time actor computes the same input).
* :class:`StandNoisePolicy`: SB3's ``ActorCriticPolicy`` whose Gaussian has, row by row, the
  fixed log-std ``stand_log_std`` on those rows. Rollout and update compute the same
  distribution from the same stored observation, so PPO's ratio stays exact.
"""

from __future__ import annotations

import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.running_mean_std import RunningMeanStd

from biped_constraint_env.command import MAX_COMMAND_M_S
from biped_constraint_env.observation import OBS_NAMES

HIP_VY = OBS_NAMES.index("hip_vy")
PINNED = {"command_m_s": MAX_COMMAND_M_S, "hip_vy": 8.0}
"""The entries read in m/s (name: the largest magnitude a fold must pass unclipped): the
command, and the hip's forward speed (a walk or a fall here stays well below 8 m/s)."""
PINNED_INDEX = {-1: MAX_COMMAND_M_S, HIP_VY: 8.0}
""":data:`PINNED` by index in the command task's observation (the command its last entry)."""


def _pinned(v, indices: list[int], value: float) -> np.ndarray:
    v = np.array(v, dtype=np.float64)  # a copy: never the caller's array
    v[indices] = value
    return v


class PinnedStats(RunningMeanStd):
    """Running mean and variance with some entries held at mean 0 and variance 1 (identity).

    Every assignment to ``mean`` or ``var`` (SB3's update, a restored snapshot) is pinned.
    """

    def __init__(self, shape: tuple[int, ...], indices, frozen: bool = False):
        """Hold ``indices`` (negative: from the end); ``frozen``: hold every entry.

        A frozen one moves with no data; a restored snapshot still sets it.
        """
        self._index, self.frozen = list(indices), frozen
        super().__init__(shape=shape)

    def update(self, arr) -> None:
        """SB3's running update, or nothing where the statistics are frozen."""
        if not self.frozen:
            super().update(arr)

    mean = property(lambda self: self._mean,
                    lambda self, v: setattr(self, "_mean", _pinned(v, self._index, 0.0)),
                    doc="The running mean (the pinned entries 0).")  # fmt: skip
    var = property(lambda self: self._var,
                   lambda self, v: setattr(self, "_var", _pinned(v, self._index, 1.0)),
                   doc="The running variance (the pinned entries 1).")  # fmt: skip


def pin_command(vecnorm, entries, frozen: bool = False) -> None:
    """Hold ``entries`` of ``vecnorm``'s observation statistics at the identity.

    ``entries``: indices (``PPOConfig.pinned_entries``: :data:`PINNED` and the entries an
    expert's gate reads); ``frozen``: hold the others where they are set too (the returns'
    statistics still move).
    """
    old = vecnorm.obs_rms
    stats = PinnedStats(old.mean.shape, list(entries), frozen)
    stats.mean, stats.var, stats.count = old.mean, old.var, old.count
    vecnorm.obs_rms = stats


class RowPolicy(ActorCriticPolicy):
    """``ActorCriticPolicy`` whose distribution depends on the observation row by row.

    SB3 builds the distribution from the actor's latent alone; every public route (rollout,
    update, prediction) here first hands the observation to :meth:`_see` and clears it after,
    so that ``_get_action_dist_from_latent`` can read what the subclass kept of it.
    """

    def _see(self, obs) -> None:
        """Keep what the distribution needs of ``obs`` (None: clear it)."""
        raise NotImplementedError

    def _with_obs(self, obs, fn):
        self._see(obs)
        try:
            return fn()
        finally:
            self._see(None)

    def forward(self, obs, deterministic: bool = False):
        """SB3's rollout pass (actions, values, log-probabilities), row by row."""
        parent = super()
        return self._with_obs(obs, lambda: parent.forward(obs, deterministic))

    def evaluate_actions(self, obs, actions):
        """SB3's update pass (values, log-probabilities, entropy), row by row."""
        parent = super()
        return self._with_obs(obs, lambda: parent.evaluate_actions(obs, actions))

    def get_distribution(self, obs):
        """The action distribution of ``obs``, row by row (``predict`` comes here)."""
        parent = super()
        return self._with_obs(obs, lambda: parent.get_distribution(obs))


class StandNoisePolicy(RowPolicy):
    """``ActorCriticPolicy`` with a fixed exploration noise on rows commanded to stand.

    ``stand_log_std``: the log-std (action units, one per action) where the command (the last
    entry of the normalised observation, pinned to the identity by :func:`pin_command`) is
    exactly 0 and, with ``stand_speed`` > 0, the hip's forward speed (pinned too) is below it
    in magnitude; elsewhere the policy's own learned ``log_std``. The weights and their names
    are ``ActorCriticPolicy``'s (the noise on those rows is a setting, not a weight).
    """

    def __init__(self, *args, stand_log_std=(), stand_speed: float = 0.0, **kwargs):
        super().__init__(*args, **kwargs)
        if self.use_sde:
            raise ValueError("stand_std_nm does not combine with use_sde")
        stand = torch.as_tensor(np.asarray(stand_log_std, np.float32))
        if stand.shape != (self.action_space.shape[0],):
            raise ValueError(f"stand_log_std needs {self.action_space.shape[0]} values, "
                             f"got {tuple(stand.shape)}")  # fmt: skip
        self.register_buffer("stand_log_std", stand, persistent=False)
        self.stand_speed = float(stand_speed)
        self._stand: torch.Tensor | None = None

    def stand_rows(self, obs: torch.Tensor) -> torch.Tensor:
        """The rows of ``obs`` (normalised, :data:`PINNED` entries in m/s) given the fixed noise."""
        obs = obs.float()  # the network's own input dtype, whichever the caller passes
        rows = obs[..., -1] == 0
        if self.stand_speed > 0:
            rows &= obs[..., HIP_VY].abs() < self.stand_speed
        return rows

    def _see(self, obs) -> None:
        self._stand = None if obs is None else self.stand_rows(obs)

    def _get_action_dist_from_latent(self, latent_pi):
        if self._stand is None:  # every public route sets the rows first
            raise RuntimeError("StandNoisePolicy: the distribution needs the observation")
        mean = self.action_net(latent_pi)
        log_std = torch.where(self._stand[:, None], self.stand_log_std, self.log_std)
        return self.action_dist.proba_distribution(mean, log_std)


def fold_pinned_inputs(
    policy, mean: np.ndarray, var: np.ndarray, eps: float, clip: float, exact: bool = True
) -> list:
    """Make a network that read the :data:`PINNED` entries normalised read them in m/s (in place).

    Its first layers (actor and critic) saw ``(x - mean) / sqrt(var + eps)`` there; with those
    inputs' weights divided by the scale and the bias moved by ``-w mean / scale``, they compute
    the same from ``x`` itself: exactly, wherever the old input was not clipped, which holds
    for every value up to the entry's bound in :data:`PINNED` (else ValueError, nothing
    changed; with ``exact=False``, for a start whose other inputs are normalised afresh and so
    not kept exactly either, folded all the same: the same up to the clip). Left as it is: an
    entry pinned already (mean 0, variance 1), or one that was only ever 0 (mean 0, variance
    below 1e-6: every command a zero), which read 0 there as the run will. Returns the entries
    folded.
    """
    todo = []
    for i, bound in PINNED_INDEX.items():
        if mean[i] == 0.0 and (var[i] == 1.0 or var[i] < 1e-6):
            continue
        scale = float(np.sqrt(var[i] + eps))
        if exact and (bound + abs(mean[i])) / scale >= clip:
            raise ValueError(f"observation entry {i} was normalised by mean {mean[i]:.3g}, "
                             f"variance {var[i]:.3g} and clipped below {bound} in "
                             f"magnitude")  # fmt: skip
        todo.append((i, float(mean[i]), scale))
    nets = (policy.mlp_extractor.policy_net, policy.mlp_extractor.value_net)
    firsts = [net[0] if len(net) else None for net in nets]
    if todo and not all(isinstance(f, torch.nn.Linear) for f in firsts):
        raise ValueError("the network has no first linear layers to take the inputs")
    with torch.no_grad():
        for first in firsts if todo else ():
            for i, m, scale in todo:
                w = first.weight[:, i].clone()
                first.weight[:, i] = w / scale
                first.bias -= w * (m / scale)
    return [i for i, _, _ in todo]


def stand_balance_callback():
    """A callback: after each rollout, the standing rows' advantages scaled down to the others'.

    PPO's gradient of a row's log-probability with respect to its action mean is
    ``(a - mean) / std**2``, of size ``1 / std``: rows with the fixed small noise pull the shared
    network about ``learned std / stand std`` times harder than the others. The rollout's
    advantages (after GAE) are normalised over the whole rollout, then the standing rows' are
    multiplied by the geometric mean over the joints of ``stand std / learned std`` at that
    rollout, so that every row's pull on the mean is of about one size. The model must not
    normalise advantages again per minibatch (:func:`training.ppo.build.make_model` turns SB3's
    ``normalize_advantage`` off with this option). The value targets are unchanged.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    class StandBalance(BaseCallback):
        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            policy, buf = self.model.policy, self.model.rollout_buffer
            if getattr(self.model, "normalize_advantage", False):
                raise RuntimeError("stand_balance: SB3 would normalise each minibatch again")
            with torch.no_grad():
                obs = torch.as_tensor(buf.observations.reshape(-1, buf.observations.shape[-1]))
                rows = policy.stand_rows(obs).numpy().reshape(buf.advantages.shape)
                factor = float(torch.exp((policy.stand_log_std - policy.log_std).mean()))
            adv = buf.advantages
            adv[...] = (adv - adv.mean()) / (adv.std() + 1e-8)
            adv[rows] *= factor
            self.logger.record("train/stand_rows", float(rows.mean()))
            self.logger.record("train/stand_advantage_scale", factor)

    return StandBalance()
