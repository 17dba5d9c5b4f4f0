"""A standing branch: one network whose actor has a second head where the command task stands.

Every PPO run from the walker told to stop walked on (``results/command_stage4``): the
walker's actor at a zero command is a walk, and exploring about it never samples a stop,
while a network trained only to stand (PPO from a random network, standing starts at a zero
command) brakes and stands from model 4 but never finds a step. ``PPOConfig.stand_branch``
gives the actor both: a second MLP (the same hidden layers) with its own action head and its
own learned log-std, which acts on the rows whose command is exactly zero **and** whose
contact state is model 4 (both feet down); every other row is the walker's. The gate is read
from the observation (the command, pinned to m/s by
:func:`training.ppo.exploration.pin_command`, and the model one-hot), so the network alone
maps an observation to its action; the critic is shared. At a zero command the walker
finishes its step into double support, the branch brakes and stands there, and a foot that
lifts hands the row back to the walker.

The branch reads the run's normalised observation through a fixed affine map and clip
(:class:`InputMap`, buffers saved with the weights), so that a branch started from another
run's actor (``stand_branch_from``) computes that run's own normalised input: exactly, for the
run's observation statistics, which such a run holds fixed (``pin_command(frozen=True)``);
entries that barely varied in the other run's statistics read 0, as they did there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from biped_constraint_env.modes import N_MODELS
from biped_constraint_env.observation import OBS_MODE
from training.ppo.exploration import RowPolicy

STAND_MODEL = N_MODELS
"""The contact state the branch acts in: model 4, both feet down."""
MODE_ENTRY = OBS_MODE.start + STAND_MODEL - 1
"""The observation's entry of model 4's one-hot."""
MIN_STD_RATIO = 0.01
"""An entry whose standard deviation in the source's statistics is below this fraction of the
run's barely varied there: the source's normalisation would blow the run's variation (and its
sensor noise) up a hundredfold and more, so the branch reads 0 for it, the value the source
saw it at (the stander's foot rate: 0.002 rad/s there, 0.42 in a walk, 0.05 of sensor noise)."""


class InputMap(nn.Module):
    """``clip(scale * x + shift, -clip, clip)``: fixed (buffers, saved with the weights)."""

    def __init__(self, n: int, clip: float = 10.0):
        super().__init__()
        self.register_buffer("scale", torch.ones(n))
        self.register_buffer("shift", torch.zeros(n))
        self.register_buffer("clip", torch.tensor(float(clip)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The fixed map of ``x`` (rows of the run's normalised observation)."""
        return torch.clamp(x * self.scale + self.shift, -self.clip, self.clip)


class StandBranchPolicy(RowPolicy):
    """An ``ActorCriticPolicy`` whose actor has a standing branch at a zero command in model 4.

    The branch: :class:`InputMap`, an MLP of the actor's hidden layers and activation, a
    linear head of the actions' size and a learned log-std (``branch_log_std_init``); the
    walker's modules and names are ``ActorCriticPolicy``'s. Rollout, update and prediction
    compute one distribution from one stored observation, so PPO's ratio stays exact.
    """

    def __init__(self, *args, branch_log_std_init: float = -3.0, **kwargs):
        self._branch_log_std_init = float(branch_log_std_init)
        super().__init__(*args, **kwargs)
        if self.use_sde:
            raise ValueError("stand_branch does not combine with use_sde")
        self._gate: torch.Tensor | None = None
        self._obs: torch.Tensor | None = None

    def _build(self, lr_schedule) -> None:
        """The branch's modules first, so that the optimizer ``super()._build`` makes holds them."""
        n_in = self.features_dim
        arch = self.net_arch if isinstance(self.net_arch, list) else self.net_arch["pi"]
        layers: list[nn.Module] = []
        for width in arch:
            layers += [nn.Linear(n_in, width), self.activation_fn()]
            n_in = width
        n_act = self.action_space.shape[0]
        self.branch_input = InputMap(self.features_dim)
        self.branch_net = nn.Sequential(*layers)
        self.branch_action = nn.Linear(n_in, n_act)
        self.branch_log_std = nn.Parameter(torch.full((n_act,), self._branch_log_std_init))
        super()._build(lr_schedule)
        if self.ortho_init:  # as SB3 initialises the walker's actor
            for module, gain in ((self.branch_net, np.sqrt(2)), (self.branch_action, 0.01)):
                module.apply(lambda m, g=gain: self.init_weights(m, gain=g))

    @staticmethod
    def gate(obs: torch.Tensor) -> torch.Tensor:
        """The rows the branch acts on: command (the last entry, in m/s) exactly 0, in model 4.

        The model-4 entry is normalised, ``(1 - mean) / std`` > 0 in model 4 and
        ``-mean / std`` < 0 elsewhere (its mean lies in (0, 1)): read by its sign.
        """
        obs = obs.float()
        return (obs[..., -1] == 0) & (obs[..., MODE_ENTRY] > 0)

    def _see(self, obs) -> None:
        if obs is None:
            self._gate = self._obs = None
        else:
            self._gate, self._obs = self.gate(obs), self.extract_features(obs).float()

    def branch_mean(self, features: torch.Tensor) -> torch.Tensor:
        """The branch's action mean of ``features`` (every row, gated or not)."""
        return self.branch_action(self.branch_net(self.branch_input(features)))

    def _get_action_dist_from_latent(self, latent_pi):
        if self._gate is None:  # every public route sets the rows first
            raise RuntimeError("StandBranchPolicy: the distribution needs the observation")
        gate = self._gate[:, None]
        mean = torch.where(gate, self.branch_mean(self._obs), self.action_net(latent_pi))
        log_std = torch.where(gate, self.branch_log_std, self.log_std)
        return self.action_dist.proba_distribution(mean, log_std)


def branch_from(policy: StandBranchPolicy, source, source_norm: dict, run_mean: np.ndarray,
                run_var: np.ndarray, run_eps: float) -> None:  # fmt: skip
    """Start ``policy``'s branch from another run's actor (in place).

    ``source``: that run's ``ActorCriticPolicy`` (the same hidden layers); ``source_norm``: its
    normaliser (:func:`training.ppo.policy_io.read_normalizer`); ``run_mean``, ``run_var``,
    ``run_eps``: the statistics this run normalises with now (pinned entries 0, 1). The
    branch's input map turns this run's normalised input into the source's: raw = x std + mean,
    then the source's ``clip((raw - mean) / sqrt(var + eps))``; entries that barely varied in
    the source's data (:data:`MIN_STD_RATIO`) read 0.
    """
    src_mean, src_var = source_norm["obs_mean"], source_norm["obs_var"]
    run_std = np.sqrt(run_var + run_eps)
    src_std = np.sqrt(src_var + source_norm["epsilon"])
    varied = src_std >= MIN_STD_RATIO * run_std
    scale = np.where(varied, run_std / src_std, 0.0)
    shift = np.where(varied, (run_mean - src_mean) / src_std, 0.0)
    actor = source.mlp_extractor.policy_net
    if [type(m) for m in actor] != [type(m) for m in policy.branch_net]:
        raise ValueError("the branch's source has other hidden layers than this run's actor")
    with torch.no_grad():
        policy.branch_net.load_state_dict(actor.state_dict())
        policy.branch_action.load_state_dict(source.action_net.state_dict())
        policy.branch_log_std.copy_(source.log_std)
        policy.branch_input.scale.copy_(torch.as_tensor(scale, dtype=torch.float32))
        policy.branch_input.shift.copy_(torch.as_tensor(shift, dtype=torch.float32))
        policy.branch_input.clip.fill_(float(source_norm["clip_obs"]))


def walker_weights(policy: StandBranchPolicy) -> dict[str, torch.Tensor]:
    """The state dict of ``policy`` without the branch: an ``MlpPolicy``'s names."""
    return {k: v for k, v in policy.state_dict().items() if not k.startswith("branch_")}


def load_source(path: Path):
    """(policy, normaliser dict, snapshot name, weights' SHA-256) of a policy directory.

    Its published snapshot, read once and checked as any untrusted snapshot (nothing
    unpickled or imported): a plain actor with observation statistics.
    """
    import hashlib

    from training.plumbing.safe_files import inside
    from training.ppo.policy_io import (
        NORMALIZER_FILE,
        POLICY_FILE,
        build_policy,
        check_weights,
        load_weights,
        open_snapshot,
        published_snapshot,
        read_config,
        read_normalizer,
    )

    cfg = read_config(path)
    if cfg.stand_branch:
        raise ValueError(f"{path} has a standing branch itself: give a plain actor")
    which, _ = published_snapshot(path)
    snap = open_snapshot(path, which)
    inside(Path(path), snap.path)
    check_weights(cfg, snap)
    policy = build_policy(cfg)
    load_weights(policy, snap)
    raw = snap.files.get(NORMALIZER_FILE)
    d = None if raw is None else read_normalizer(snap.name(NORMALIZER_FILE), cfg.obs_dim(), raw)
    if d is None or not d["norm_obs"]:
        raise ValueError(f"{path}: its snapshot holds no observation statistics")
    return policy, d, which, hashlib.sha256(snap.files[POLICY_FILE]).hexdigest()
