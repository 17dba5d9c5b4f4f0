"""A set of experts: one network whose rows are acted on by the expert their observation selects.

``PPOConfig.policy = "experts"`` with ``[[experts]]`` tables: SB3's ``ActorCriticPolicy`` (its
actor and critic: the first expert, ``walk``, acting wherever no other expert's condition
holds) and one more actor per table (an MLP of the same hidden layers and activation, a linear
head, a learned log-std), with its own critic where the table says ``critic = "own"`` (else the
first expert's). The gate is data: each table's ``when`` names observation entries
(:func:`biped_constraint_env.observation.observation_names`) and the value each must equal;
the first table whose every entry equals its value acts on the row. Those entries are read
as the env gives them: the run's normaliser holds them at the identity (mean 0, variance 1,
:func:`training.ppo.exploration.pin_command`), so the network alone maps an observation to its
action and the gate needs nothing but the observation.

For the command task (``training/configs/ppo_command_scratch_50hz.toml``): ``stand`` where
the command is 0 and both feet are down (``mode_4 = 1``), ``brake`` where the command is 0
otherwise, ``walk`` everywhere else. Every part starts from random weights as SB3 initialises
its own (orthogonal, the action heads' gain 0.01) and learns in the run. Rollout, update and
prediction compute one distribution and one value from one stored observation, so PPO's ratio
stays exact.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from training.ppo.exploration import RowPolicy

EXPERT_KEYS = ("name", "when", "critic")
CRITICS = ("own", "shared")


def check_experts(experts, names: tuple[str, ...]) -> tuple:
    """The ``[[experts]]`` tables as the policy takes them, or ValueError naming the fault.

    Returns ``((name, ((entry index, value), ...), own critic), ...)``; ``names``: the
    observation's entry names.
    """
    out, seen = [], {"walk"}
    for k, e in enumerate(experts):
        where = f"[[experts]] entry {k + 1}"
        if not isinstance(e, dict) or set(e) - set(EXPERT_KEYS) or {"name", "when"} - set(e):
            raise ValueError(f"{where}: takes name, when (a table of observation entry = "
                             f"value) and critic ({' or '.join(CRITICS)}), got {e!r}")  # fmt: skip
        name = e["name"]
        if not isinstance(name, str) or not name.isidentifier() or name in seen:
            raise ValueError(f"{where}: name must be a new identifier (not 'walk', the "
                             f"first expert's), got {name!r}")  # fmt: skip
        seen.add(name)
        when = e["when"]
        if not isinstance(when, dict) or not when:
            raise ValueError(f"{where}: when must be a table of observation entry = value")
        gate = []
        for entry, value in when.items():
            if entry not in names:
                raise ValueError(f"{where}: when names {entry!r}, not an observation entry of "
                                 f"this env ({', '.join(names)})")  # fmt: skip
            if isinstance(value, bool) or not isinstance(value, int | float) or \
                    not np.isfinite(value):  # fmt: skip
                raise ValueError(f"{where}: when {entry} must be a number, got {value!r}")
            gate.append((names.index(entry), float(value)))
        critic = e.get("critic", "shared")
        if critic not in CRITICS:
            raise ValueError(f"{where}: critic must be one of {CRITICS}, got {critic!r}")
        out.append((name, tuple(gate), critic == "own"))
    return tuple(out)


def gate_entries(experts: tuple) -> list[int]:
    """The observation entries the gate of :func:`check_experts`' ``experts`` reads."""
    return sorted({i for _, gate, _ in experts for i, _ in gate})


def expert_rows(obs: torch.Tensor, experts: tuple) -> torch.Tensor:
    """Which expert acts on each row of ``obs``: 0 the first (``walk``), k the k-th table's."""
    obs = obs.float()
    which = torch.zeros(obs.shape[:-1], dtype=torch.long, device=obs.device)
    for k in range(len(experts), 0, -1):  # the first table that matches wins: set it last
        _, gate, _ = experts[k - 1]
        match = torch.ones_like(which, dtype=torch.bool)
        for i, value in gate:
            match &= obs[..., i] == value
        which = torch.where(match, k, which)
    return which


def _mlp(n_in: int, arch: list[int], activation) -> tuple[nn.Sequential, int]:
    layers: list[nn.Module] = []
    for width in arch:
        layers += [nn.Linear(n_in, width), activation()]
        n_in = width
    return nn.Sequential(*layers), n_in


class ExpertsPolicy(RowPolicy):
    """SB3's ``ActorCriticPolicy`` (the first expert) and one actor per ``[[experts]]`` table.

    ``experts``: :func:`check_experts`' tuple. The extra actors are ``actors[k]`` (MLP),
    ``heads[k]`` (linear) and ``log_stds[k]``; an own critic ``critics[name]`` (MLP and a
    linear value head).
    """

    def __init__(self, *args, experts: tuple = (), **kwargs):
        self.experts = tuple((n, tuple(map(tuple, g)), bool(c)) for n, g, c in experts)
        super().__init__(*args, **kwargs)
        if self.use_sde:
            raise ValueError('policy = "experts" does not combine with use_sde')
        self._which: torch.Tensor | None = None
        self._obs: torch.Tensor | None = None

    def _build(self, lr_schedule) -> None:
        """The experts' modules first, so that the optimizer ``super()._build`` makes holds them."""
        arch = self.net_arch if isinstance(self.net_arch, list) else self.net_arch["pi"]
        n_act = self.action_space.shape[0]
        self.actors, self.heads = nn.ModuleList(), nn.ModuleList()
        self.log_stds = nn.ParameterList()
        self.critics = nn.ModuleDict()
        for name, _, own in self.experts:
            net, width = _mlp(self.features_dim, arch, self.activation_fn)
            self.actors.append(net)
            self.heads.append(nn.Linear(width, n_act))
            self.log_stds.append(nn.Parameter(torch.full((n_act,), float(self.log_std_init))))
            if own:
                vnet, _ = _mlp(self.features_dim, arch, self.activation_fn)
                self.critics[name] = nn.Sequential(vnet, nn.Linear(width, 1))
        super()._build(lr_schedule)
        if self.ortho_init:  # as SB3 initialises the first expert's actor and critic
            for module, gain in ((self.actors, np.sqrt(2)), (self.heads, 0.01)):
                module.apply(lambda m, g=gain: self.init_weights(m, gain=g))
            for critic in self.critics.values():
                critic[0].apply(lambda m: self.init_weights(m, gain=np.sqrt(2)))
                critic[1].apply(lambda m: self.init_weights(m, gain=1.0))

    def expert_rows(self, obs: torch.Tensor) -> torch.Tensor:
        """Which expert acts on each row of ``obs`` (:func:`expert_rows`)."""
        return expert_rows(obs, self.experts)

    def _see(self, obs) -> None:
        if obs is None:
            self._which = self._obs = None
        else:
            self._which, self._obs = self.expert_rows(obs), self.extract_features(obs).float()

    def forward(self, obs, deterministic: bool = False):
        """SB3's rollout pass; an own critic's rows its values."""
        actions, values, log_prob = super().forward(obs, deterministic)
        return actions, self._values(obs, values), log_prob

    def evaluate_actions(self, obs, actions):
        """SB3's update pass; an own critic's rows its values."""
        values, log_prob, entropy = super().evaluate_actions(obs, actions)
        return self._values(obs, values), log_prob, entropy

    def predict_values(self, obs):
        """The values of ``obs`` (bootstrapping); an own critic's rows its values."""
        return self._values(obs, super().predict_values(obs))

    def _values(self, obs, values: torch.Tensor) -> torch.Tensor:
        if not len(self.critics):
            return values
        which, features = self.expert_rows(obs), self.extract_features(obs).float()
        for k, (name, _, own) in enumerate(self.experts, start=1):
            if own:
                values = torch.where((which == k)[:, None], self.critics[name](features), values)
        return values

    def _get_action_dist_from_latent(self, latent_pi):
        if self._which is None:  # every public route sets the rows first
            raise RuntimeError("ExpertsPolicy: the distribution needs the observation")
        mean, log_std = self.action_net(latent_pi), self.log_std
        for k in range(1, len(self.experts) + 1):
            rows = (self._which == k)[:, None]
            mean = torch.where(rows, self.heads[k - 1](self.actors[k - 1](self._obs)), mean)
            log_std = torch.where(rows, self.log_stds[k - 1], log_std)
        return self.action_dist.proba_distribution(mean, log_std)


def actor_parameters(policy: ExpertsPolicy, name: str) -> list:
    """The parameters of expert ``name``'s actor: its MLP, action head and learned log-std."""
    if name == "walk":
        return [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters(),
                policy.log_std]  # fmt: skip
    k = [n for n, _, _ in policy.experts].index(name)
    return [*policy.actors[k].parameters(), *policy.heads[k].parameters(), policy.log_stds[k]]


def copy_actor(policy: ExpertsPolicy, dst: str, src: str) -> None:
    """Expert ``dst``'s actor set to a copy of ``src``'s (in place).

    Adam forgets ``dst``'s moments, so its next steps are a new start's.
    """
    with torch.no_grad():
        for d, s in zip(actor_parameters(policy, dst), actor_parameters(policy, src), strict=True):
            d.copy_(s)
            policy.optimizer.state.pop(d, None)


def set_frozen(policy: ExpertsPolicy, names) -> None:
    """The actors of ``names`` do not learn (no gradient reaches them); every other one does."""
    names = set(names)
    for name in ["walk", *(n for n, _, _ in policy.experts)]:
        for q in actor_parameters(policy, name):
            q.requires_grad_(name not in names)
