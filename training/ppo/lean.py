"""Stable-Baselines3 PPO with a lean rollout and update: the same numbers, less Python.

:class:`LeanPPO` is SB3's :class:`~stable_baselines3.PPO` (its save format, schedules,
callbacks, logger records and rollout buffer) whose ``collect_rollouts`` and ``train`` compute
the policy's forward pass, its Gaussian's samples, log-probabilities and entropy with the same
torch operations in the same order as SB3's ``ActorCriticPolicy`` and ``DiagGaussianDistribution``,
without building a ``torch.distributions.Normal`` (and validating its arguments) per call nor
going through ``nn.Module.__call__`` per layer; its minibatches are gathered by torch from the
buffer's tensors (:func:`minibatches`) and Adam steps all parameters at once (torch's
``foreach`` implementation, the same arithmetic per element). A run's weights, normaliser and logs are bit for
bit those of SB3's PPO (``tests/test_lean_ppo.py`` trains both side by side).

It applies to the plain actor-critic: SB3's ``ActorCriticPolicy`` class itself with a diagonal
Gaussian, no gSDE, no squashing, a flatten features extractor shared by actor and critic, and
hidden layers that are ``Linear`` and ``Tanh`` or ``ReLU``; any other policy
(a subclass, other layers) runs SB3's own code unchanged (:func:`lean_applies`).
"""

from __future__ import annotations

import math

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.type_aliases import RolloutBufferSamples
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import FlattenExtractor
from stable_baselines3.common.utils import explained_variance
from torch import nn
from torch.nn import functional as F

_LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))  # as torch's Normal.log_prob computes it
_ENTROPY_CONST = 0.5 + 0.5 * math.log(2 * math.pi)  # as torch's Normal.entropy computes it


def _layers(seq: nn.Sequential):
    """``seq``'s layers as plain functions, each as its module computes it (None: another)."""
    out = []
    for m in seq:
        if type(m) is nn.Linear:
            out.append((F.linear, (m.weight, m.bias)))
        elif type(m) is nn.Tanh:
            out.append((th.tanh, ()))
        elif type(m) is nn.ReLU and not m.inplace:
            out.append((F.relu, ()))
        else:
            return None
    return out


def lean_applies(policy, rollout_buffer=None) -> bool:
    """Whether :class:`LeanPPO`'s lean path computes exactly what SB3 computes for ``policy``."""
    ok = (
        type(policy) is ActorCriticPolicy
        and isinstance(policy.action_dist, DiagGaussianDistribution)
        and not policy.use_sde
        and not policy.squash_output
        and policy.share_features_extractor
        and type(policy.features_extractor) is FlattenExtractor
        and isinstance(policy.action_space, spaces.Box)
        and isinstance(policy.observation_space, spaces.Box)
        and _layers(policy.mlp_extractor.policy_net) is not None
        and _layers(policy.mlp_extractor.value_net) is not None
        and type(policy.action_net) is nn.Linear
        and type(policy.value_net) is nn.Linear
    )
    return ok and (rollout_buffer is None or type(rollout_buffer) is RolloutBuffer)


def _run(layers, x):
    """``x`` through ``layers`` (:func:`_layers`)."""
    for fn, args in layers:
        x = fn(x, *args)
    return x


class _Forward:
    """The policy's forward pass as SB3 computes it, layer by layer with plain functions."""

    def __init__(self, policy: ActorCriticPolicy):
        """The layers of ``policy`` (:func:`lean_applies` holds)."""
        self.policy = policy
        self.pi = _layers(policy.mlp_extractor.policy_net)
        self.vf = _layers(policy.mlp_extractor.value_net)

    def latents(self, obs: th.Tensor):
        """(latent_pi, latent_vf) of raw observations (SB3: ``preprocess_obs``: ``float()``)."""
        features = obs.float().flatten(1, -1)  # FlattenExtractor (nn.Flatten: start_dim 1)
        return _run(self.pi, features), _run(self.vf, features)

    def value(self, latent_vf):
        """The critic's output layer."""
        v = self.policy.value_net
        return F.linear(latent_vf, v.weight, v.bias)

    def mean_std(self, latent_pi):
        """(mean, std) as DiagGaussianDistribution.proba_distribution builds its Normal."""
        a = self.policy.action_net
        mean = F.linear(latent_pi, a.weight, a.bias)
        return mean, th.ones_like(mean) * self.policy.log_std.exp()

    @staticmethod
    def log_prob(actions, mean, std):
        """Normal(mean, std).log_prob(actions) summed over the action (SB3's log_prob)."""
        var = std**2
        lp = -((actions - mean) ** 2) / (2 * var) - std.log() - _LOG_SQRT_2PI
        return lp.sum(dim=1)

    def act(self, obs: th.Tensor):
        """(actions, values, log_probs) as ``ActorCriticPolicy.forward`` samples them."""
        latent_pi, latent_vf = self.latents(obs)
        values = self.value(latent_vf)
        mean, std = self.mean_std(latent_pi)
        eps = th.empty(mean.shape, dtype=mean.dtype).normal_()  # Normal.rsample's draw
        actions = mean + eps * std
        return actions, values, self.log_prob(actions, mean, std)

    def predict_values(self, obs: th.Tensor):
        """``ActorCriticPolicy.predict_values``."""
        return self.value(_run(self.vf, obs.float().flatten(1, -1)))

    def evaluate(self, obs: th.Tensor, actions: th.Tensor):
        """(values, log_prob, entropy) as ``ActorCriticPolicy.evaluate_actions``."""
        latent_pi, latent_vf = self.latents(obs)
        mean, std = self.mean_std(latent_pi)
        log_prob = self.log_prob(actions, mean, std)
        values = self.value(latent_vf)
        entropy = (_ENTROPY_CONST + th.log(std)).sum(dim=1)
        return values, log_prob, entropy


_FIELDS = ("observations", "actions", "values", "log_probs", "advantages", "returns")


def minibatches(buffer: RolloutBuffer, batch_size: int):
    """``RolloutBuffer.get(batch_size)``'s minibatches: the same permutation and values.

    The flattened buffer becomes tensors once, and each minibatch is gathered from them by
    torch, instead of numpy fancy indexing and a copy into a new tensor per field.
    """
    assert buffer.full, ""
    n = buffer.buffer_size * buffer.n_envs
    indices = np.random.permutation(n)  # SB3's draw, from numpy's global generator
    if not buffer.generator_ready:
        for name in _FIELDS:
            buffer.__dict__[name] = buffer.swap_and_flatten(buffer.__dict__[name])
        buffer.generator_ready = True
    data = [th.as_tensor(buffer.__dict__[name]) for name in _FIELDS]
    obs, actions = data[0], data[1].float()  # SB3 casts the actions to float32
    flat = [t.reshape(n) for t in data[2:]]  # SB3 flattens the (n, 1) columns
    order = th.as_tensor(indices)
    for start in range(0, n, batch_size):
        idx = order[start : start + batch_size]
        yield RolloutBufferSamples(obs[idx], actions[idx], *(t[idx] for t in flat))


class LeanPPO(PPO):
    """SB3's PPO, its rollouts and updates computed leanly (see the module docstring)."""

    def _lean(self):
        """The forward pass of the lean path, or None where SB3's own code must run.

        Built anew for each rollout and update, so that it follows the policy's current
        layers and parameters whatever replaced them in between.
        """
        if not lean_applies(self.policy, self.rollout_buffer):
            return None
        return _Forward(self.policy)

    def collect_rollouts(self, env, callback, rollout_buffer, n_rollout_steps: int) -> bool:
        """SB3's ``OnPolicyAlgorithm.collect_rollouts``, the same numbers (module docstring)."""
        fwd = self._lean()
        if fwd is None:
            return super().collect_rollouts(env, callback, rollout_buffer, n_rollout_steps)
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        n_steps = 0
        rollout_buffer.reset()
        callback.on_rollout_start()
        low, high = self.action_space.low, self.action_space.high
        while n_steps < n_rollout_steps:
            with th.no_grad():
                actions, values, log_probs = fwd.act(th.as_tensor(self._last_obs))
            actions = actions.numpy()
            clipped_actions = np.clip(actions, low, high)
            new_obs, rewards, dones, infos = env.step(clipped_actions)
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())  # as SB3: the callbacks read these names
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            n_steps += 1
            for idx in np.flatnonzero(dones).tolist():  # a time limit bootstraps, as SB3
                info = infos[idx]
                if info.get("terminal_observation") is not None and info.get(
                    "TimeLimit.truncated", False
                ):
                    terminal_obs = self.policy.obs_to_tensor(info["terminal_observation"])[0]
                    with th.no_grad():
                        terminal_value = fwd.predict_values(terminal_obs)[0]
                    rewards[idx] += self.gamma * terminal_value
            rollout_buffer.add(
                self._last_obs, actions, rewards, self._last_episode_starts, values, log_probs
            )
            self._last_obs = new_obs
            self._last_episode_starts = dones
        with th.no_grad():
            values = fwd.predict_values(th.as_tensor(new_obs))
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    def train(self) -> None:
        """SB3's ``PPO.train``, the same numbers and logger records (module docstring)."""
        fwd = self._lean()
        if fwd is None:
            return super().train()
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        clip_range = self.clip_range(self._current_progress_remaining)
        if self.clip_range_vf is not None:
            clip_range_vf = self.clip_range_vf(self._current_progress_remaining)
        entropy_losses, pg_losses, value_losses, clip_fractions = [], [], [], []
        continue_training = True
        params = list(self.policy.parameters())
        optimizer = self.policy.optimizer
        if type(optimizer) is th.optim.Adam:  # torch's multi-tensor Adam: the same numbers
            for group in optimizer.param_groups:
                group["foreach"] = True
        for epoch in range(self.n_epochs):
            approx_kl_divs = []
            for rollout_data in minibatches(self.rollout_buffer, self.batch_size):
                values, log_prob, entropy = fwd.evaluate(
                    rollout_data.observations, rollout_data.actions
                )
                values = values.flatten()
                advantages = rollout_data.advantages
                if self.normalize_advantage and len(advantages) > 1:
                    advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
                ratio = th.exp(log_prob - rollout_data.old_log_prob)
                policy_loss_1 = advantages * ratio
                policy_loss_2 = advantages * th.clamp(ratio, 1 - clip_range, 1 + clip_range)
                policy_loss = -th.min(policy_loss_1, policy_loss_2).mean()
                pg_losses.append(policy_loss.item())
                clip_fractions.append(th.mean((th.abs(ratio - 1) > clip_range).float()).item())
                if self.clip_range_vf is None:
                    values_pred = values
                else:
                    values_pred = rollout_data.old_values + th.clamp(
                        values - rollout_data.old_values, -clip_range_vf, clip_range_vf
                    )
                value_loss = F.mse_loss(rollout_data.returns, values_pred)
                value_losses.append(value_loss.item())
                entropy_loss = -th.mean(entropy)
                entropy_losses.append(entropy_loss.item())
                loss = policy_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss
                with th.no_grad():
                    log_ratio = log_prob - rollout_data.old_log_prob
                    approx_kl_div = th.mean((th.exp(log_ratio) - 1) - log_ratio).cpu().numpy()
                    approx_kl_divs.append(approx_kl_div)
                if self.target_kl is not None and approx_kl_div > 1.5 * self.target_kl:
                    continue_training = False
                    if self.verbose >= 1:
                        print(f"Early stopping at step {epoch} due to reaching max kl: "
                              f"{approx_kl_div:.2f}")  # fmt: skip
                    break
                optimizer.zero_grad()
                loss.backward()
                th.nn.utils.clip_grad_norm_(params, self.max_grad_norm)
                optimizer.step()
            self._n_updates += 1
            if not continue_training:
                break
        explained_var = explained_variance(
            self.rollout_buffer.values.flatten(), self.rollout_buffer.returns.flatten()
        )
        record = self.logger.record
        record("train/entropy_loss", np.mean(entropy_losses))
        record("train/policy_gradient_loss", np.mean(pg_losses))
        record("train/value_loss", np.mean(value_losses))
        record("train/approx_kl", np.mean(approx_kl_divs))
        record("train/clip_fraction", np.mean(clip_fractions))
        record("train/loss", loss.item())
        record("train/explained_variance", explained_var)
        record("train/std", th.exp(self.policy.log_std).mean().item())
        record("train/n_updates", self._n_updates, exclude="tensorboard")
        record("train/clip_range", clip_range)
        if self.clip_range_vf is not None:
            record("train/clip_range_vf", clip_range_vf)
