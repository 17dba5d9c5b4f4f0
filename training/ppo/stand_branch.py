"""A standing branch: one network whose actor has a second head where the command task stands.

Every PPO run from the walker told to stop walked on (``results/command_stage4``): the
walker's actor at a zero command is a walk, and exploring about it never samples a stop,
while a network trained only to stand (PPO from a random network, standing starts at a zero
command) brakes and stands from model 4 but never finds a step. ``PPOConfig.stand_branch``
gives the network both: a second actor (an MLP of the same hidden layers, its own action head
and learned log-std) and a second critic, which act on the rows whose command is exactly zero
**and** whose contact state is model 4 (both feet down); every other row is the walker's. The
gate is read from the observation (the command, pinned to m/s by
:func:`training.ppo.exploration.pin_command`, and the model one-hot), so the network alone
maps an observation to its action; a foot that lifts hands the row back to the walker. The
design: at a zero command the walker finishes its step into double support and the branch
brakes and stands there. What it gave (``results/command_stage5``): a stander in the branch
keeps standing under PPO only at a small learning rate or frozen (``stand_branch_frozen``),
and the walker's torques lift the old toe at once, so a walk's double support ends within one
control period and the branch gets a row only once the walker has nearly stopped; no run
stopped. (The command reward's ``load`` term pays for pressing that toe instead.)

The branch reads the run's normalised observation through a fixed affine map and clip
(:class:`InputMap`, buffers saved with the weights), so that a branch started from another
run's actor (``stand_branch_from``) computes that run's own normalised input: exactly, for the
run's observation statistics, which such a run holds fixed (``pin_command(frozen=True)``);
entries that barely varied in the other run's statistics read 0, as they did there.

The branch may look further ahead than the walker (``PPOConfig.stand_gamma``): its rows are
discounted by their own factor in the advantages (:class:`BranchDiscountBuffer`, a discount that
depends on the state, as in White 2017's transition-based discounting) and in the bootstrap of
an episode cut by its time limit (:func:`truncation_discount`). A stander that comes to rest and
drifts over seconds is then seen falling by its critic while the walker keeps its own short
discount (a walker's transition into a branch row still bootstraps from the branch's
longer-horizon value, so the walker's returns near a stop change too). With
``PPOConfig.stand_gamma_rows`` "zero_command" the longer discount holds on every row commanded
to stop, in any contact state: the walker's braking steps before both feet are down then see
the stop's fall seconds ahead too, while the walk at any other command keeps its short
horizon. A run started from another (``init_from``) does not inherit the option: give it again.

A third actor may take the braking (``PPOConfig.brake_branch``): the rows commanded to stop
outside model 4 (a walk's last steps before both feet are down), which are otherwise the
walker's. It reads the walker's normalised input (no map), has the walker's shape and starts as
a copy of the walker's actor, so the network at its start acts exactly as before; from there the
braking learns in its own weights, and the walk at every commanded speed, whose rows it never
acts on, does not move with it (with one actor the braking's updates carry into the walk at slow
commands: ``results/command_stage18``). Its rows' values stay the walker's critic's.
"""

from __future__ import annotations

import numpy as np
import torch
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.callbacks import BaseCallback
from torch import nn

from biped_constraint_env.modes import N_MODELS
from biped_constraint_env.observation import OBS_MODE
from training.ppo.exploration import RowPolicy

STAND_MODEL = N_MODELS
"""The contact state the branch acts in: model 4, both feet down."""
MODE_ENTRY = OBS_MODE.start + STAND_MODEL - 1
"""The observation's entry of model 4's one-hot."""
BRANCH_ACTOR = ("branch_net.", "branch_action.", "branch_log_std")
"""Name prefixes of the branch actor's parameters (the others of the branch: its critic)."""
MIN_STD_RATIO = 0.01
"""An entry whose standard deviation in the source's statistics is below this fraction of the
run's barely varied there: the source's normalisation would blow the run's variation (and its
sensor noise) up a hundredfold and more, so the branch reads 0 for it, the value the source
saw it at (the stander's foot rate: 0.002 rad/s there, 0.42 in a walk, 0.05 of sensor noise)."""


def zero_command(obs: torch.Tensor, entry: int = -1) -> torch.Tensor:
    """The rows of ``obs`` whose command (entry ``entry``, in m/s) is exactly 0."""
    return obs.float()[..., entry] == 0


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


def actor_parameters(policy) -> list:
    """The branch actor's parameters of ``policy`` (:data:`BRANCH_ACTOR`; none without a branch)."""
    return [q for name, q in policy.named_parameters() if name.startswith(BRANCH_ACTOR)]


BRAKE_ACTOR = ("brake_net.", "brake_action.", "brake_log_std")
"""Name prefixes of the braking actor's parameters (``brake_branch``)."""


def brake_parameters(policy) -> list:
    """The braking actor's parameters of ``policy`` (:data:`BRAKE_ACTOR`; none without one)."""
    return [q for name, q in policy.named_parameters() if name.startswith(BRAKE_ACTOR)]


def copy_walker_to_brake(policy) -> None:
    """Set the braking actor to the walker's actor (MLP, head, learned log-std), in place."""
    with torch.no_grad():
        policy.brake_net.load_state_dict(policy.mlp_extractor.policy_net.state_dict())
        policy.brake_action.load_state_dict(policy.action_net.state_dict())
        policy.brake_log_std.copy_(policy.log_std)


def walker_parameters(policy) -> list:
    """The walker's actor parameters of ``policy``: its MLP, action head and learned log-std."""
    return [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters(),
            policy.log_std]  # fmt: skip


def freeze_actor(policy, which: str = "branch") -> None:
    """Keep an actor as it is: no gradient reaches it, so Adam never moves it.

    ``which``: "branch" (:func:`actor_parameters`) or "walker" (:func:`walker_parameters`).
    """
    params = {"branch": actor_parameters, "walker": walker_parameters}[which](policy)
    for q in params:
        q.requires_grad_(False)


def _shape(m: nn.Module) -> tuple:
    """The arguments that remake a layer of an MLP: Linear (in, out), an activation ()."""
    return (m.in_features, m.out_features) if isinstance(m, nn.Linear) else ()


class StandBranchPolicy(RowPolicy):
    """An ``ActorCriticPolicy`` with a standing branch at a zero command in model 4.

    The branch: :class:`InputMap`; an actor (an MLP of the walker's hidden layers and
    activation, a linear head of the actions' size, a learned log-std,
    ``branch_log_std_init``) and a critic (the same MLP shape, a linear value head, times the
    fixed ``branch_value_scale``). The walker's modules and names are ``ActorCriticPolicy``'s.
    Rollout, update and prediction compute one distribution and one value from one stored
    observation, so PPO's ratio stays exact.
    """

    def __init__(self, *args, branch_log_std_init: float = -3.0, brake_branch: bool = False,
                 **kwargs):  # fmt: skip
        self._branch_log_std_init = float(branch_log_std_init)
        self.brake_branch = bool(brake_branch)
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
        self.branch_value_net = nn.Sequential(*[m.__class__(*_shape(m)) for m in layers])
        self.branch_value = nn.Linear(n_in, 1)
        self.register_buffer("branch_value_scale", torch.tensor(1.0))
        if self.brake_branch:  # the walker's shape; set from the walker's weights after the build
            self.brake_net = nn.Sequential(*[m.__class__(*_shape(m)) for m in layers])
            self.brake_action = nn.Linear(n_in, n_act)
            self.brake_log_std = nn.Parameter(torch.zeros(n_act))
        super()._build(lr_schedule)
        if self.brake_branch:
            copy_walker_to_brake(self)
        if self.ortho_init:  # as SB3 initialises the walker's actor and critic
            gains = ((self.branch_net, np.sqrt(2)), (self.branch_action, 0.01),
                     (self.branch_value_net, np.sqrt(2)), (self.branch_value, 1.0))  # fmt: skip
            for module, gain in gains:
                module.apply(lambda m, g=gain: self.init_weights(m, gain=g))

    @staticmethod
    def gate(obs: torch.Tensor) -> torch.Tensor:
        """The rows the branch acts on: command (the last entry, in m/s) exactly 0, in model 4.

        The model-4 entry is normalised, ``(1 - mean) / std`` > 0 in model 4 and
        ``-mean / std`` <= 0 elsewhere: read by its sign, for a mean below 1 (statistics from
        data that was not all model 4; :func:`branch_from` refuses held ones that were).
        """
        return zero_command(obs) & (obs.float()[..., MODE_ENTRY] > 0)

    @staticmethod
    def brake_gate(obs: torch.Tensor) -> torch.Tensor:
        """The braking actor's rows: command exactly 0, outside model 4 (read as :meth:`gate`)."""
        return zero_command(obs) & ~(obs.float()[..., MODE_ENTRY] > 0)

    def _see(self, obs) -> None:
        if obs is None:
            self._gate = self._brake = self._obs = None
        else:
            self._gate, self._obs = self.gate(obs), self.extract_features(obs).float()
            self._brake = self.brake_gate(obs) if self.brake_branch else None

    def forward(self, obs, deterministic: bool = False):
        """SB3's rollout pass; the gated rows' values the branch's critic's."""
        actions, values, log_prob = super().forward(obs, deterministic)
        return actions, self._gated_values(obs, values), log_prob

    def evaluate_actions(self, obs, actions):
        """SB3's update pass; the gated rows' values the branch's critic's."""
        values, log_prob, entropy = super().evaluate_actions(obs, actions)
        return self._gated_values(obs, values), log_prob, entropy

    def predict_values(self, obs):
        """The values of ``obs`` (bootstrapping); the gated rows' the branch's critic's."""
        return self._gated_values(obs, super().predict_values(obs))

    def _gated_values(self, obs, values: torch.Tensor) -> torch.Tensor:
        features = self.extract_features(obs).float()
        return torch.where(self.gate(obs)[:, None], self.branch_values(features), values)

    def branch_values(self, features: torch.Tensor) -> torch.Tensor:
        """The branch critic's values of ``features`` (every row), in the run's return units."""
        latent = self.branch_value_net(self.branch_input(features))
        return self.branch_value(latent) * self.branch_value_scale

    def branch_mean(self, features: torch.Tensor) -> torch.Tensor:
        """The branch's action mean of ``features`` (every row, gated or not)."""
        return self.branch_action(self.branch_net(self.branch_input(features)))

    def _get_action_dist_from_latent(self, latent_pi):
        if self._gate is None:  # every public route sets the rows first
            raise RuntimeError("StandBranchPolicy: the distribution needs the observation")
        gate = self._gate[:, None]
        mean, log_std = self.action_net(latent_pi), self.log_std
        if self.brake_branch:
            brake = self._brake[:, None]
            brake_mean = self.brake_action(self.brake_net(self._obs))
            mean = torch.where(brake, brake_mean, mean)
            log_std = torch.where(brake, self.brake_log_std, log_std)
        mean = torch.where(gate, self.branch_mean(self._obs), mean)
        log_std = torch.where(gate, self.branch_log_std, log_std)
        return self.action_dist.proba_distribution(mean, log_std)


def branch_from(policy: StandBranchPolicy, source, source_norm: dict, run_mean: np.ndarray,
                run_var: np.ndarray, run_eps: float, run_ret_var: float = 1.0) -> None:  # fmt: skip
    """Start ``policy``'s branch from another run's actor (in place).

    ``source``: that run's ``ActorCriticPolicy`` (the same hidden layers); ``source_norm``: its
    normaliser (:func:`training.ppo.policy_io.read_normalizer`); ``run_mean``, ``run_var``,
    ``run_eps``: the statistics this run normalises with now (pinned entries 0, 1);
    ``run_ret_var``: the variance of its returns (its rewards are divided by the square root:
    the source's critic, which learned returns divided by its own, is rescaled to them). The
    branch's input map turns this run's normalised input into the source's: raw = x std + mean,
    then the source's ``clip((raw - mean) / sqrt(var + eps))``; entries that barely varied in
    the source's data (:data:`MIN_STD_RATIO`) read 0.
    """
    if not run_mean[MODE_ENTRY] < 1.0:
        raise ValueError("the run's statistics saw nothing but model 4: the gate cannot read "
                         "the model from them")  # fmt: skip
    src_mean, src_var = source_norm["obs_mean"], source_norm["obs_var"]
    run_std = np.sqrt(run_var + run_eps)
    src_std = np.sqrt(src_var + source_norm["epsilon"])
    varied = src_std >= MIN_STD_RATIO * run_std
    scale = np.where(varied, run_std / src_std, 0.0)
    shift = np.where(varied, (run_mean - src_mean) / src_std, 0.0)
    actor, critic = source.mlp_extractor.policy_net, source.mlp_extractor.value_net
    for theirs, mine in ((actor, policy.branch_net), (critic, policy.branch_value_net)):
        if [type(m) for m in theirs] != [type(m) for m in mine]:
            raise ValueError("the branch's source has other hidden layers than this run's")
    eps = source_norm["epsilon"]
    value_scale = np.sqrt(source_norm["ret_var"] + eps) / np.sqrt(run_ret_var + eps)
    with torch.no_grad():
        policy.branch_net.load_state_dict(actor.state_dict())
        policy.branch_action.load_state_dict(source.action_net.state_dict())
        policy.branch_log_std.copy_(source.log_std)
        policy.branch_value_net.load_state_dict(critic.state_dict())
        policy.branch_value.load_state_dict(source.value_net.state_dict())
        policy.branch_value_scale.fill_(float(value_scale))
        policy.branch_input.scale.copy_(torch.as_tensor(scale, dtype=torch.float32))
        policy.branch_input.shift.copy_(torch.as_tensor(shift, dtype=torch.float32))
        policy.branch_input.clip.fill_(float(source_norm["clip_obs"]))


DISCOUNT_ROWS = ("branch", "zero_command")
"""Where ``stand_gamma`` holds: the branch's rows, or every row whose command is 0."""


def discount_gate(obs: torch.Tensor, rows: str = "branch", command_entry: int = -1):
    """The rows discounted by ``stand_gamma``, a boolean per row of ``obs``.

    ``rows="branch"``: :meth:`StandBranchPolicy.gate`'s; ``"zero_command"``: every row whose
    command (entry ``command_entry``, in m/s) is exactly 0.
    """
    if check_rows(rows) == "branch":
        return StandBranchPolicy.gate(obs)
    return zero_command(obs, command_entry)


def check_rows(rows: str) -> str:
    """``rows`` if it is one of :data:`DISCOUNT_ROWS`, else ValueError."""
    if rows not in DISCOUNT_ROWS:
        raise ValueError(f"rows must be one of {DISCOUNT_ROWS}, got {rows!r}")
    return rows


class BranchDiscountBuffer(RolloutBuffer):
    """SB3's rollout buffer whose GAE discounts the branch's rows by ``stand_gamma``.

    A transition from a row of ``rows`` (:func:`discount_gate` of its stored observation:
    the branch's by default) discounts what follows it by ``stand_gamma``, every other one by
    the run's ``gamma``; with the two equal this is SB3's GAE exactly.
    """

    def __init__(self, *args, stand_gamma: float, rows: str = "branch", command_entry: int = -1,
                 **kwargs):  # fmt: skip
        super().__init__(*args, **kwargs)
        if not 0.0 < stand_gamma < 1.0:  # 1: a stander's value would grow without bound
            raise ValueError(f"stand_gamma must be in (0, 1), got {stand_gamma!r}")
        self.stand_gamma, self.rows = float(stand_gamma), check_rows(rows)
        self.command_entry = int(command_entry)

    def step_gammas(self) -> np.ndarray:
        """The discount of every stored transition, (buffer_size, n_envs)."""
        obs = torch.as_tensor(self.observations)
        gate = discount_gate(obs, self.rows, self.command_entry).numpy()
        return np.where(gate, self.stand_gamma, self.gamma).astype(np.float32)

    def compute_returns_and_advantage(self, last_values: torch.Tensor, dones: np.ndarray) -> None:
        """GAE(lambda) and the lambda-returns, as SB3's, with each row's own discount."""
        last_values = last_values.clone().cpu().numpy().flatten()
        gammas = self.step_gammas()
        last_gae_lam = 0.0
        for step in reversed(range(self.buffer_size)):
            if step == self.buffer_size - 1:
                next_non_terminal = 1.0 - dones.astype(np.float32)
                next_values = last_values
            else:
                next_non_terminal = 1.0 - self.episode_starts[step + 1]
                next_values = self.values[step + 1]
            g = gammas[step]
            delta = self.rewards[step] + g * next_values * next_non_terminal - self.values[step]
            last_gae_lam = delta + g * self.gae_lambda * next_non_terminal * last_gae_lam
            self.advantages[step] = last_gae_lam
        self.returns = self.advantages + self.values


def learn_rows_callback(rows: str = "zero_command"):
    """A callback: after each rollout, only the rows commanded to stop keep their advantages.

    ``PPOConfig.learn_rows`` "zero_command": the rollout's advantages (after GAE) are normalised
    over the rows whose command is 0 (:func:`zero_command`: the walker's braking steps and the
    branch's rows), and every other row's is set to 0, so that its clipped PPO term, and with no
    entropy bonus its whole policy loss, is 0: the actor learns from the stops alone (the
    critics from every row). SB3 must not normalise each minibatch again
    (:func:`training.ppo.build.make_model` turns ``normalize_advantage`` off).
    """
    from stable_baselines3.common.callbacks import BaseCallback

    if rows != "zero_command":
        raise ValueError(f"rows must be 'zero_command', got {rows!r}")

    class LearnRows(BaseCallback):
        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            buf = self.model.rollout_buffer
            if getattr(self.model, "normalize_advantage", False):
                raise RuntimeError("learn_rows: SB3 would normalise each minibatch again")
            obs = torch.as_tensor(buf.observations.reshape(-1, buf.observations.shape[-1]))
            keep = zero_command(obs).numpy().reshape(buf.advantages.shape)
            adv = buf.advantages
            if keep.any():
                kept = adv[keep]
                adv[keep] = (kept - kept.mean()) / (kept.std() + 1e-8)
            adv[~keep] = 0.0
            self.logger.record("train/learn_rows_fraction", float(keep.mean()))

    return LearnRows()


def truncation_discount(stand_gamma: float, rows: str = "branch"):
    """A callback: an episode cut by its time limit on a ``rows`` row bootstraps at ``stand_gamma``.

    SB3 adds ``gamma * V(terminal observation)`` to the reward of a transition that ends an
    episode by its time limit, after the callbacks' step; this adds ``(stand_gamma - gamma) *
    V`` first on the rows whose transition started on such a row (:func:`discount_gate`), so
    that their bootstrap uses that discount, as :class:`BranchDiscountBuffer` does inside a rollout.
    """
    check_rows(rows)

    class TruncationDiscount(BaseCallback):
        def _on_step(self) -> bool:
            m = self.model
            buf = getattr(m, "rollout_buffer", None)  # the schedule's discount where it sets one
            extra = getattr(buf, "stand_gamma", stand_gamma) - m.gamma
            dones, infos, rewards = (self.locals[k] for k in ("dones", "infos", "rewards"))
            if extra == 0 or not dones.any():
                return True
            entry = getattr(buf, "command_entry", -1)
            gate = discount_gate(torch.as_tensor(m._last_obs), rows, entry).numpy()
            for i in np.flatnonzero(dones & gate):
                info = infos[i]
                if info.get("terminal_observation") is None or not info.get("TimeLimit.truncated"):
                    continue
                obs = m.policy.obs_to_tensor(info["terminal_observation"])[0]
                with torch.no_grad():
                    rewards[i] += extra * float(m.policy.predict_values(obs)[0, 0])
            return True

    return TruncationDiscount()
