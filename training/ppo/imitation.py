"""Demonstrations from the model controller (a teacher) and behaviour cloning into a PPO policy.

The teacher (:class:`training.controller.model_controller.ModelController`) labels
observations with its torques; the student is Stable-Baselines3's ``MlpPolicy`` (the
network PPO goes on to train), its action in [-1, 1]^5 scaled per joint by ``gear`` [N m]
(as Walker2d's gear), its observations normalised inside the network by fixed statistics
of the demonstrations (:class:`FixedNormalizer`).

* :func:`collect` rolls episodes out in the env, the executed torque being the teacher's (DART:
  plus Gaussian noise, so that the data cover the states the student's errors lead to) or the
  student's own (DAgger), and records the teacher's label of every visited observation;
* :func:`fit` regresses the policy's mean action onto the labels (mean-squared error in units
  of the gear).

:func:`training.ppo.train.imitation_warm_start` chains them (DART, DAgger rounds) before PPO.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from biped_constraint_env.env import ConstrainedBipedEnv


@dataclass
class Dataset:
    """Observations (n, 24) and the teacher's normalised labels (n, 5), both float32."""

    obs: np.ndarray
    act: np.ndarray

    def __len__(self) -> int:
        return len(self.obs)

    def __add__(self, other: Dataset) -> Dataset:
        return Dataset(np.concatenate([self.obs, other.obs]), np.concatenate([self.act, other.act]))


@dataclass
class Rollouts:
    """What :func:`collect` saw: the labelled data and, per episode, steps and end reason."""

    data: Dataset
    steps: list[int]
    ends: list[str]


def collect(
    env: ConstrainedBipedEnv,
    teacher: Callable[[np.ndarray], np.ndarray],
    gear: np.ndarray,
    seeds: list[int],
    max_periods: int,
    noise_nm: float | np.ndarray = 0.0,
    student: Callable[[np.ndarray], np.ndarray] | None = None,
    rng: np.random.Generator | None = None,
    progress=None,
) -> Rollouts:
    """Roll out one episode per seed; label every observation with the teacher.

    Args:
        env: the single env (its kwargs set the task).
        teacher: obs (24,) -> torques (5,) [N m].
        gear: (5,) [N m] per unit action; labels are teacher / gear, clipped to [-1, 1].
        seeds: reset seeds, one episode each.
        max_periods: cap on control periods per episode.
        noise_nm: std of Gaussian torque noise added to the executed action [N m] (scalar or
            (5,)): DART's noise injection.
        student: obs (24,) -> normalised action (5,); when given, the student acts (DAgger),
            else the teacher does.
        rng: noise generator.
        progress: a callable wrapping the seed iterable (e.g. a progress bar), or None.
    """
    rng = rng or np.random.default_rng(0)
    gear = np.asarray(gear, dtype=np.float64)
    limit = env.settings.action.torque_limit_nm
    obs_l, act_l, steps, ends = [], [], [], []
    for seed in progress(seeds) if progress else seeds:
        obs, info = env.reset(seed=int(seed))
        if hasattr(teacher, "reset"):  # a teacher with a start phase: per episode
            teacher.reset()
        for _ in range(max_periods):
            label = np.asarray(teacher(obs), dtype=np.float64)
            obs_l.append(obs.astype(np.float32))
            act_l.append(np.clip(label / gear, -1.0, 1.0).astype(np.float32))
            tau = label if student is None else np.clip(student(obs), -1, 1) * gear
            tau = np.clip(tau + noise_nm * rng.standard_normal(5), -limit, limit)
            obs, _, terminated, truncated, info = env.step(tau)
            if terminated or truncated:
                break
        steps.append(info["steps_completed"])
        ends.append(info["termination_reason"] or "cap")
    return Rollouts(Dataset(np.array(obs_l), np.array(act_l)), steps, ends)


def obs_statistics(obs: np.ndarray, floor: float = 1e-2) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of the observations (variance floored, e.g. for constant entries)."""
    mean = obs.mean(axis=0).astype(np.float64)
    var = np.maximum(obs.var(axis=0).astype(np.float64), floor**2)
    return mean, var


def _actor_params(policy) -> list:
    """The parameters behind the policy's mean action (extractor, policy MLP, action head)."""
    return [
        *policy.features_extractor.parameters(),
        *policy.mlp_extractor.policy_net.parameters(),
        *policy.action_net.parameters(),
    ]


def _joint_weights(weights: np.ndarray | None):
    """Per-joint weights of the squared error, normalised to mean 1 (default: equal)."""
    w = torch.ones(5) if weights is None else torch.as_tensor(weights, dtype=torch.float32)
    return w / w.mean()


def _mean_action(policy, x):
    """The policy's mean action (before clipping) for a batch of raw observations."""
    return policy.action_net(policy.mlp_extractor.forward_actor(policy.extract_features(x)))


def _loss(policy, x, y, w):
    """Weighted mean-squared error of the policy's mean action against the labels."""
    return torch.mean(w * (_mean_action(policy, x) - y) ** 2)


def fit(
    policy,
    data: Dataset,
    epochs: int,
    batch_size: int = 512,
    lr: float = 1e-3,
    seed: int = 0,
    weights: np.ndarray | None = None,
    log: Callable[[str], None] | None = None,
) -> float:
    """Regress ``policy``'s mean action (an SB3 ActorCriticPolicy) onto the labels.

    Only the actor (shared extractor, policy MLP, action head) is trained; Adam with a cosine
    learning-rate decay over the epochs. ``weights`` (5,) weight each joint's squared error
    (default: equal; the stance ankle is the joint whose errors the contacts tolerate least).
    Returns the final epoch's weighted mean-squared error (in units of the gear).
    """
    gen = torch.Generator().manual_seed(seed)
    x = torch.as_tensor(data.obs, dtype=torch.float32)
    y = torch.as_tensor(data.act, dtype=torch.float32)
    w = _joint_weights(weights)
    opt = torch.optim.Adam(_actor_params(policy), lr=lr)
    n_batches = max(len(x) // batch_size, 1)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=epochs * n_batches)
    loss_mean = float("nan")
    policy.set_training_mode(True)
    for epoch in range(epochs):
        perm = torch.randperm(len(x), generator=gen)
        total = 0.0
        for b in range(n_batches):
            idx = perm[b * batch_size : (b + 1) * batch_size]
            loss = _loss(policy, x[idx], y[idx], w)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item()
        loss_mean = total / n_batches
        if log and (epoch + 1) % max(epochs // 4, 1) == 0:
            log(f"  epoch {epoch + 1}/{epochs}: mse {loss_mean:.2e}")
    policy.set_training_mode(False)
    return loss_mean


class Anchor:
    """A few behaviour-cloning steps at a time on fixed data, with one persistent optimiser.

    Interleaved with PPO's updates (kickstarting / the iterative supervised + policy-gradient
    design), it keeps the policy near the teacher where the demonstrations are, while PPO
    moves it where its return improves.
    """

    def __init__(
        self,
        policy,
        data: Dataset,
        lr: float,
        batch_size: int = 512,
        weights: np.ndarray | None = None,
        seed: int = 0,
    ):
        """Anchor ``policy``'s actor to ``data`` (see :func:`fit` for ``weights``)."""
        self.policy = policy
        self.x = torch.as_tensor(data.obs, dtype=torch.float32)
        self.y = torch.as_tensor(data.act, dtype=torch.float32)
        self.w = _joint_weights(weights)
        self.batch_size = batch_size
        self.gen = torch.Generator().manual_seed(seed)
        self.opt = torch.optim.Adam(_actor_params(policy), lr=lr)

    def steps(self, n: int) -> float:
        """``n`` gradient steps; returns their mean weighted squared error."""
        total = 0.0
        for _ in range(n):
            idx = torch.randint(len(self.x), (self.batch_size,), generator=self.gen)
            loss = _loss(self.policy, self.x[idx], self.y[idx], self.w)
            self.opt.zero_grad()
            loss.backward()
            self.opt.step()
            total += loss.item()
        return total / max(n, 1)


def student_fn(policy):
    """Obs (24,) -> the policy's deterministic normalised action (5,), as a numpy function."""

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            x = torch.as_tensor(obs[None, :], dtype=torch.float32)
            return _mean_action(policy, x).numpy()[0]

    return act


class FixedNormalizer(BaseFeaturesExtractor):
    """SB3 features extractor that normalises observations by fixed statistics.

    Part of the policy (saved in ``model.zip``), so that the network alone maps the env's raw
    observation to its action: ``clip((obs - mean) / sqrt(var + 1e-8), -10, 10)``, as
    VecNormalize does, with the demonstrations' mean and variance frozen.
    """

    def __init__(self, observation_space, mean, var):
        """``mean``, ``var``: (24,) statistics of the observations."""
        super().__init__(observation_space, observation_space.shape[0])
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.sqrt(torch.as_tensor(var, dtype=torch.float32) + 1e-8))

    def forward(self, obs):
        """Normalised observations."""
        return torch.clamp((obs - self.mean) / self.std, -10.0, 10.0)
