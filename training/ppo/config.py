"""The PPO training configuration and the seed ranges of training, selection and evaluation.

Shared by :mod:`training.ppo.train` (which trains), :mod:`training.evaluation.evaluate` (which
rebuilds
the policy and its env from a run's ``config.toml``) and :mod:`training.ppo.sweep`. The comment
after each field is its ``--help`` text.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from biped_constraint_env.settings import with_keys

MAX_RESTARTS = 100
"""The most restarts ``[restart]`` allows (its ``max``)."""


@dataclass
class PPOConfig:
    """PPO settings (numbers that differ from SB3's defaults say why)."""

    RETIRED: ClassVar[dict[str, str]] = {
        "curriculum_env": "removed with curriculum_steps (a curriculum of lenient checks never "
        "produced a walker; docs/ablations.md)",
        "curriculum_steps": "removed with [curriculum_env] (a curriculum of lenient checks never "
        "produced a walker; docs/ablations.md)",
    }

    env_id: str = "ConstrainedBiped-v0"  # Gymnasium id of the env
    env: dict = field(default_factory=dict)  # [env] table: gym.make's keyword arguments, the
    # env the policy runs in (evaluations start as it does: no reference-state starts);
    # flags: --env KEY=VALUE ... (TOML values) on top of the file's table
    train_env: dict = field(default_factory=dict)  # [train_env] table: what the training env
    # changes on top of [env] (reference-state starts, pushes, randomised models...)
    start_curriculum: dict = field(default_factory=dict)  # [start_curriculum] table: training
    # episodes start from `first` (a start's name or weights) until the mean length of the last
    # 100 training episodes reaches `until_episode_s` [s], then from [train_env]'s start
    # ({}: none; the switch is saved with the checkpoint)
    schedule: tuple[dict, ...] = ()  # [[schedule]] tables (config file only), each
    # {at = ENV_STEPS, train_env = {...}, gamma = X, stand_gamma = X, learning_rate = X,
    # copy = {EXPERT = EXPERT}, frozen = [EXPERT, ...]}: from the first rollout at or after
    # `at` env steps, its train_env keys replace those in force (every training row starts
    # again in that env), its discounts and learning rate (under the run's lr_schedule) the
    # run's; with policy "experts", the actors it names in copy start there as copies of
    # others', and those in frozen stop learning (until an entry gives another list); entries
    # in increasing `at`, each holding until the next (stages inside one run; phase_at)
    train_episode_s: float = 0.0  # > 0: training episodes end (truncated) after this [s];
    # SB3 bootstraps the value there; evaluation keeps the env's 30 s
    seed: int = 0  # drives the network's initialisation, the training starts and the demos
    total_timesteps: int = 3_000_000  # env steps of PPO in all (a resumed run keeps its own)
    n_envs: int = 16  # environments stepped together (one compiled batch with vec="batched")
    vec: str = "batched"  # "batched" (one compiled call), "subproc" or "dummy" (SB3's)
    env_threads: int = 1  # numba threads of the batched env: 1 next to torch on 2 cores
    n_steps: int = 256  # rollout length per env (x 16 envs = 4096 samples per update)
    batch_size: int = 512  # PPO minibatch size
    n_epochs: int = 10  # PPO epochs per update
    learning_rate: float = 3e-4  # Adam learning rate of PPO
    lr_schedule: str = "constant"  # "constant" or "linear" (decays to 0 at total_timesteps)
    target_kl: float = 0.0  # > 0: stop an update's epochs when the KL exceeds 1.5 x this
    gamma: float = 0.99  # discount factor
    gamma_final: float = 0.0  # > 0: the discount ramps linearly from gamma to this over the
    # env steps gamma_ramp gives (a short horizon while the start is learned, then a long one)
    gamma_ramp: tuple[int, ...] = ()  # (from, to): the env steps of that ramp
    gae_lambda: float = 0.95  # GAE lambda
    clip_range: float = 0.2  # PPO clipping
    ent_coef: float = 0.0  # entropy bonus
    log_std_init: float = -3.0  # initial log std of the actions: std 0.05 (7.5 N m); the flat
    # stance foot tolerates only about +-11 N m of ankle moment before an end unloads; SB3's 0
    # (150 N m) breaks contact at once
    use_sde: bool = False  # generalized state-dependent exploration (gSDE) instead of
    # independent Gaussian noise per period
    sde_sample_freq: int = -1  # with use_sde: periods between new noise matrices (-1: rollout)
    net_arch: tuple[int, ...] = (256, 256)  # hidden layers of the actor and the critic
    activation: str = "tanh"  # hidden activation: "tanh" (SB3's default), "relu" or "elu"
    policy: str = "mlp"  # the network: "mlp" (SB3's actor and critic) or "experts" (one actor
    # more per [[experts]] table, the gate data over named observation entries;
    # training.ppo.experts)
    experts: tuple[dict, ...] = ()  # [[experts]] tables (config file only), each {name = S,
    # when = {ENTRY = VALUE, ...}, critic = "own" or "shared"}: that actor acts on the rows
    # whose named observation entries (biped_constraint_env.observation.observation_names)
    # all equal their values, the first table that matches; elsewhere the first actor, "walk"
    torch_threads: int = 1  # torch threads (1: the env and torch do not fight for 2 cores)
    update_threads: int = 0  # torch threads in PPO's updates, when the env is idle
    # (0: torch_threads; 2 on an otherwise idle 2-core machine, 1 with two runs side by side)
    eval_freq: int = 100_000  # env steps between evaluations (they select best/)
    eval_episodes: int = 10  # episodes per evaluation, on the selection seeds (all at once,
    # in the batched env)
    select_by: str = "mean"  # best/: the most steps ("mean", "min") or the mean return
    # (the fewest steps of its episodes first, then the mean); "protocol" (task "command"):
    # the command protocol's rows (start, tracking, stop, restart, sequences) on eval_episodes
    # selection episodes each, the most goals met first; the run stops once every goal holds
    # in stop_evals consecutive evaluations
    stop_min_steps: int = 0  # > 0: the run stops by itself once every selection episode
    # completed at least this many steps in stop_evals consecutive evaluations (its own
    # criterion, on the selection seeds); 0: it trains to total_timesteps
    stop_evals: int = 2  # consecutive evaluations the stop criterion must hold
    stop_confirm_episodes: int = 0  # > 0: an evaluation whose every episode met the stop
    # criterion runs the same network on this many more selection episodes (the next seeds);
    # it meets the criterion only if they all do too, and its row, its score for best/ and
    # the stop read all of its episodes (0: the evaluation's episodes alone)
    restart: dict = field(default_factory=dict)  # [restart] table: a network that has not
    # found the step draws again: at every `every` env steps, while fewer than `max` restarts
    # were made, if the training episodes that ended in the last `window` env steps completed
    # fewer than `min_steps` steps in all, the network, its noise and its optimiser start
    # again from the initial draw of seed + 1000 x (restart number) ({}: never; the restarts
    # are saved with the checkpoint)
    checkpoint_freq: int = 250_000  # env steps between checkpoints (resume continues there)
    base_controller: str = ""  # "model": learn a residual on the model controller ("" = none)
    gear: tuple[float, ...] = (150.0,)  # N m per unit action, one value or one per joint

    # imitation warm start (teacher "" = none): DART demonstrations of the model controller,
    # DAgger rounds, behaviour cloning into the policy network PPO then trains
    teacher: str = ""  # "model", "model:NAME" (training/controller/gains/NAME.json) or "model:PATH"
    bc_episodes0: int = 40  # DART episodes of the teacher (round 0)
    bc_noise_nm: float = 0.4  # std of the torque noise injected into every collected episode
    bc_rounds: int = 10  # DAgger rounds (the student acts, the teacher labels)
    bc_episodes: int = 30  # student episodes per DAgger round
    bc_periods0: int = 2000  # cap on control periods per DART episode (10 s)
    bc_periods: int = 600  # cap per DAgger episode: short, so rounds dwell on the start
    bc_grad_steps: int = 20_000  # gradient steps of the first and last fit (a third between)
    bc_lr: float = 1e-3  # learning rate of the behaviour cloning
    bc_ankle_weight: float = 1.0  # weight of the stance ankle's error (the swing ankle: half)
    log_std_joints: tuple[float, ...] = ()  # 5 values: initial log std per joint (overrides
    # log_std_init; the stance ankle tolerates far less noise than the hip)
    action_std_nm: float = 0.0  # > 0: initial action std [N m] on every joint (overrides
    # log_std_init; the std of joint j is action_std_nm / gear_j in action units)
    stand_std_nm: float = 0.0  # > 0 (task "command"): training's exploration noise [N m, every
    # joint] on the rows commanded to stand (a zero command), fixed; the learned std elsewhere.
    # The network then reads the command and the hip's forward speed in m/s, not normalised
    # (training.ppo.exploration)
    stand_speed_m_s: float = 0.0  # > 0: that noise only where the hip's forward speed is also
    # below this [m/s] (a walk told to stop keeps the learned noise until it has slowed down)
    stand_balance: bool = False  # with stand_std_nm: those rows' advantages scaled by their
    # std over the learned std (geometric mean over joints), so that a row's pull on the
    # network's mean does not grow as its noise shrinks (training.ppo.exploration)
    stand_branch: bool = False  # (task "command") the network gets a standing branch: its
    # own actor (MLP, head, learned std) and critic, acting where the command is 0 in model 4
    # (both feet down); the command and hip speed then read in m/s (training.ppo.stand_branch)
    stand_branch_from: str = ""  # with stand_branch and init_from: a policy directory whose
    # actor, learned std and critic start the branch instead of random ones; the run's
    # observation statistics then stay the start's (the returns' still move)
    stand_branch_frozen: bool = False  # with stand_branch: the branch's actor does not learn
    # (its critic does): a stage in which only the walker learns to hand over to it
    brake_branch: bool = False  # with stand_branch: a third actor (the walker's shape) acts on
    # the rows commanded to stop outside model 4 (the braking steps, else the walker's), started
    # as a copy of the walker's actor where the start has none (training.ppo.stand_branch)
    learn_rows: str = "all"  # the rows whose advantages train the actor: "all", or
    # "zero_command" (with stand_branch: only the rows commanded to stop, the walker's braking
    # steps and the branch's; the other rows' advantages are 0, so the walk at a speed changes
    # only as the shared weights carry the braking's updates) (training.ppo.stand_branch)
    walker_frozen: bool = False  # with stand_branch: the walker's actor (its MLP, head and
    # learned std) does not learn (its critic does): a stage in which only the branch learns to
    # hold what a walker hands it, the walk at every speed kept as it is (its std, as in any
    # stage, the config's initial one where it sets one; its input's statistics still move)
    stand_gamma: float = 0.0  # > 0, with stand_branch: the discount of the rows the branch acts
    # on (the walker's stay gamma): a stander that sees a slow drift's fall seconds ahead
    stand_gamma_rows: str = "branch"  # where stand_gamma holds: "branch" (command 0 in model
    # 4) or "zero_command" (command 0 in any contact state: the walker's braking steps too)
    action_bias_nm: tuple[float, ...] = ()  # 5 values: the initial bias of the network's
    # action mean [N m] per joint (its last layer's bias, learned from there like any weight:
    # a random network whose first actions pass the mid-stride start)
    critic_warmup: int = 0  # rollouts at the start of PPO in which only the critic learns
    bc_anchor_steps: int = 0  # behaviour-cloning steps on the imitation data after each PPO
    # update (kickstarting; 0 = off)
    bc_anchor_lr: float = 1e-4  # learning rate of those steps
    out_dir: Path = Path("runs")  # where the run directory is created
    resume: str = ""  # a run directory to continue (to its own saved total)
    init_from: str = ""  # a policy directory whose published snapshot (weights, normaliser)
    # starts this new run: a second stage of training; the network must match; the initial
    # exploration noise is still this config's (log_std_joints, action_std_nm) where it sets one
    init_normalizer: str = "snapshot"  # with init_from: "snapshot" continues the policy's
    # observation and return statistics; "fresh" starts them anew from this run's own data
    # (a stage whose task differs: the earlier task's statistics clip what it never saw)
    progress: bool = True  # progress bars

    def validate(self) -> None:
        """Refuse a value out of its range or choices (ValueError naming the flag)."""
        for name, lo, hi in _RANGES:
            v = getattr(self, name)
            vals = v if isinstance(v, tuple) else (v,)
            for x in vals:
                if not lo <= x <= hi:
                    raise ValueError(f"--{_flag(name)} must be in [{lo}, {hi}], got {v!r}")
        for name, allowed in _choices().items():
            if getattr(self, name) not in allowed:
                raise ValueError(
                    f"--{_flag(name)} must be one of {sorted(allowed)}, got {getattr(self, name)!r}"
                )
        for name, sizes in (
            ("gear", (1, 5)),
            ("log_std_joints", (0, 5)),
            ("action_bias_nm", (0, 5)),
            ("gamma_ramp", (0, 2)),
            ("net_arch", tuple(range(1, 9))),
        ):
            if len(getattr(self, name)) not in sizes:
                raise ValueError(f"--{_flag(name)} takes {' or '.join(map(str, sizes))} values")
        if (self.gamma_final > 0) != (len(self.gamma_ramp) == 2) or self.gamma_ramp[:1] > \
                self.gamma_ramp[1:]:  # fmt: skip
            raise ValueError("--gamma-final and --gamma-ramp FROM TO (FROM <= TO) go together")
        if self.batch_size > self.n_steps * self.n_envs:
            raise ValueError("--batch-size must be at most --n-steps x --n-envs")  # fmt: skip
        self._check_schedule_entries()  # before any phase's env is read
        from biped_constraint_env.reference import OWN_REFERENCE, REFERENCES
        from biped_constraint_env.settings import make_settings

        for table in ("env", "train_env"):
            if "render_mode" in getattr(self, table):
                raise ValueError(f"[{table}] render_mode is not a setting of a config (the "
                                 f"commands render their own figures)")  # fmt: skip
        # shipped references only: a config names no file
        for table in ("env", "train_env"):
            ref = getattr(self, table).get("reference")
            if ref is not None and ref not in (*REFERENCES, OWN_REFERENCE):
                raise ValueError(f"[{table}] reference must be a shipped name {REFERENCES} "
                                 f"or {OWN_REFERENCE!r}, "
                                 f"got {ref!r}")  # fmt: skip
        for name, kwargs in (("env", self.env_kwargs), ("train_env", self.train_env_kwargs)):
            try:
                make_settings(**kwargs())
            except (ValueError, TypeError) as e:
                raise ValueError(f"[{name}]: {e}") from None
        if self.init_normalizer != "snapshot" and not self.init_from:
            raise ValueError("--init-normalizer goes with --init-from")
        if self.select_by == "protocol" and self.settings().command is None:
            raise ValueError("--select-by protocol runs the command protocol: it needs an env "
                             "with a command ([env] task = \"command\")")  # fmt: skip
        self._check_schedule()
        self._check_experts()
        self._check_start_curriculum()  # on the valid training env
        self._check_restart()
        self._check_stand_noise()

    @property
    def pins_command(self) -> bool:
        """Whether the network reads the command and the hip speed in m/s (not normalised)."""
        return self.stand_std_nm > 0 or self.stand_branch or self.policy == "experts"

    def obs_names(self) -> tuple[str, ...]:
        """The names of the policy's observation entries, in order."""
        from biped_constraint_env.observation import observation_names

        return observation_names(self.settings().observation.blocks)

    def pinned_entries(self) -> list[int]:
        """The observation entries the normaliser holds at the identity.

        Read as the env gives them: the command and the hip's forward speed, and every entry
        an expert's gate reads.
        """
        from training.ppo.exploration import PINNED

        names = self.obs_names()
        out = {names.index(n) for n in PINNED}
        if self.policy == "experts":
            from training.ppo.experts import check_experts, gate_entries

            out |= set(gate_entries(check_experts(self.experts, names)))
        return sorted(out)

    def _check_experts(self) -> None:
        """Refuse ``[[experts]]`` that do not fit the policy or the env (ValueError)."""
        from training.ppo.experts import check_experts

        if (self.policy == "experts") != bool(self.experts):
            raise ValueError("--policy experts and [[experts]] tables go together")
        if not self.experts:
            return
        check_experts(self.experts, self.obs_names())
        for name, on in (("stand_branch", self.stand_branch), ("stand_std_nm", self.stand_std_nm),
                         ("use_sde", self.use_sde), ("teacher", self.teacher)):  # fmt: skip
            if on:
                raise ValueError(f"--policy experts does not combine with {name}")
        if "command_m_s" not in self.obs_names() and self.stand_gamma > 0:
            raise ValueError("--stand-gamma reads the command: it needs [env] task = "
                             "\"command\"")  # fmt: skip

    def _check_stand_noise(self) -> None:
        """Refuse ``stand_std_nm`` or ``stand_branch`` where they mean nothing."""
        if self.stand_branch_from and not (self.stand_branch and self.init_from):
            raise ValueError("--stand-branch-from goes with --stand-branch and --init-from")
        if self.stand_branch_frozen and not self.stand_branch:
            raise ValueError("--stand-branch-frozen goes with --stand-branch")
        if self.brake_branch and not self.stand_branch:
            raise ValueError("--brake-branch goes with --stand-branch")
        if self.learn_rows != "all" and not self.stand_branch:
            raise ValueError("--learn-rows goes with --stand-branch")
        if self.learn_rows != "all" and self.stand_balance:
            raise ValueError("--learn-rows and --stand-balance both set the advantages: give one")
        if self.walker_frozen and not self.stand_branch:
            raise ValueError("--walker-frozen goes with --stand-branch")
        if self.walker_frozen and self.stand_branch_frozen and not self.brake_branch:
            raise ValueError("--walker-frozen and --stand-branch-frozen together leave no actor "
                             "to learn")  # fmt: skip
        if self.learn_rows != "all" and self.ent_coef != 0:
            raise ValueError("--learn-rows needs --ent-coef 0 (an entropy bonus moves every "
                             "actor's noise on every row)")  # fmt: skip
        if self.stand_gamma > 0 and not (self.stand_branch or self.policy == "experts"):
            raise ValueError("--stand-gamma goes with --stand-branch or --policy experts")
        if self.policy == "experts" and self.stand_gamma_rows == "branch" and self.stand_gamma:
            raise ValueError("--stand-gamma with --policy experts holds where the command is 0: "
                             "give --stand-gamma-rows zero_command")  # fmt: skip
        if self.stand_gamma_rows != "branch" and self.stand_gamma <= 0:
            raise ValueError("--stand-gamma-rows goes with --stand-gamma")
        if self.stand_gamma >= 1.0:
            raise ValueError(f"--stand-gamma must be below 1 (0: off), got {self.stand_gamma!r}")
        if self.stand_branch_from and self.init_normalizer != "snapshot":
            raise ValueError("--stand-branch-from maps the start's normalised input: it needs "
                             "--init-normalizer snapshot")  # fmt: skip
        if self.stand_std_nm <= 0:
            if self.stand_speed_m_s > 0 or self.stand_balance:
                raise ValueError("--stand-speed-m-s and --stand-balance go with --stand-std-nm")
        elif self.stand_std_nm < 1e-3:
            raise ValueError(f"--stand-std-nm must be 0 (off) or at least 1e-3 N m, got "
                             f"{self.stand_std_nm!r}")  # fmt: skip
        elif self.stand_branch:
            raise ValueError("--stand-std-nm and --stand-branch are two ways to explore at a "
                             "zero command: give one")  # fmt: skip
        if not self.pins_command:
            return
        flag = "--stand-std-nm" if self.stand_std_nm > 0 else "--stand-branch"
        from biped_constraint_env.settings import make_settings

        for s in (self.settings(), make_settings(**self.train_env_kwargs())):
            blocks = s.observation.blocks
            if not blocks or blocks[-1] != "command":
                raise ValueError(f"{flag} needs the command as the observation's last "
                                 f"entry ([env] task = \"command\")")  # fmt: skip
            if s.action.unit_actions and self.stand_std_nm > 0:
                raise ValueError("--stand-std-nm is a torque noise: it needs [env] action = "
                                 "\"torque\"")  # fmt: skip
        small = ("target_kl (the standing rows' small noise would dominate the KL)",
                 self.target_kl > 0 and self.stand_std_nm > 0)  # fmt: skip
        for name, on in (("use_sde", self.use_sde), ("teacher", self.teacher), small):
            if on:
                raise ValueError(f"{flag} does not combine with {name}")

    SCHEDULE_KEYS = ("at", "train_env", "gamma", "stand_gamma", "learning_rate", "copy",
                     "frozen")  # fmt: skip

    def _check_schedule_entries(self) -> None:
        """Refuse a ``[[schedule]]`` entry with a wrong key or value (ValueError naming it)."""
        if self.schedule and self.start_curriculum:
            raise ValueError("[[schedule]] and [start_curriculum] both change the training "
                             "starts: give the starts in a [[schedule]] entry")  # fmt: skip
        last = 0
        for k, e in enumerate(self.schedule):
            where = f"[[schedule]] entry {k + 1}"
            unknown = sorted(set(e) - set(self.SCHEDULE_KEYS))
            if unknown or "at" not in e or len(e) < 2:
                more = ", ".join(self.SCHEDULE_KEYS[1:])
                raise ValueError(f"{where}: takes at (env steps) and one or more of {more}, "
                                 f"got {sorted(e)}")  # fmt: skip
            at = e["at"]
            if isinstance(at, bool) or not isinstance(at, int) or not last < at <= _BIG:
                raise ValueError(f"{where}: at must be a whole number of env steps above the "
                                 f"entry before's ({last}), got {at!r}")  # fmt: skip
            last = at
            for name, lo, hi in (("gamma", 0.0, 1.0), ("stand_gamma", 0.0, 0.999999),
                                 ("learning_rate", 0.0, 1.0)):  # fmt: skip
                v = e.get(name)
                if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)
                                      or not lo < v <= hi):  # fmt: skip
                    raise ValueError(f"{where}: {name} must be in ({lo}, {hi}], got {v!r}")
            if "gamma" in e and self.gamma_final > 0:
                raise ValueError(f"{where}: gamma and --gamma-final both set the discount: "
                                 f"give one")  # fmt: skip
            if "stand_gamma" in e and self.stand_gamma <= 0:
                raise ValueError(f"{where}: stand_gamma needs the run's --stand-gamma (> 0)")
            if ("copy" in e or "frozen" in e) and self.policy != "experts":
                raise ValueError(f"{where}: copy and frozen name experts: they need --policy "
                                 f"experts")  # fmt: skip
            names = ["walk", *(x.get("name") for x in self.experts if isinstance(x, dict))]
            copy = e.get("copy", {})
            if not isinstance(copy, dict) or any(
                d not in names or src not in names or d == src for d, src in copy.items()
            ):
                raise ValueError(f"{where}: copy must be a table of expert = the expert it "
                                 f"starts as a copy of, over {names}, got {copy!r}")  # fmt: skip
            frozen = e.get("frozen", [])
            if not isinstance(frozen, list | tuple) or any(n not in names for n in frozen):
                raise ValueError(f"{where}: frozen must be a list of experts of {names}, "
                                 f"got {frozen!r}")  # fmt: skip
            if "train_env" in e:
                if not isinstance(e["train_env"], dict) or not e["train_env"]:
                    raise ValueError(f"{where}: train_env must be a table of [train_env] keys")
                if "render_mode" in e["train_env"]:
                    raise ValueError(f"{where}: train_env render_mode is not a setting of a "
                                     f"config")  # fmt: skip

    def _check_schedule(self) -> None:
        """Refuse a ``[[schedule]]`` phase whose training env cannot run.

        Each phase's training env is made (its settings validated) and must observe what the
        first phase's does (the network's input is fixed when it is made).
        """
        from biped_constraint_env.settings import make_settings

        if not self.schedule:
            return
        first = make_settings(**self.train_env_kwargs()).observation.blocks
        for k, e in enumerate(self.schedule):
            where, at = f"[[schedule]] entry {k + 1}", e["at"]
            if "train_env" in e:
                try:
                    blocks = make_settings(**self.train_env_kwargs(at)).observation.blocks
                except (ValueError, TypeError) as err:
                    raise ValueError(f"{where}: train_env: {err}") from None
                if blocks != first:
                    raise ValueError(f"{where}: train_env changes the observation ({first} to "
                                     f"{blocks}): the network's input is fixed")  # fmt: skip

    def phase_at(self, env_steps: int) -> int:
        """The ``[[schedule]]`` entries in force at ``env_steps``: how many have begun (0: none)."""
        return sum(e["at"] <= env_steps for e in self.schedule)

    def _scheduled(self, name: str, env_steps: int, default):
        """The last value of ``name`` the entries begun at ``env_steps`` give, else ``default``."""
        for e in reversed(self.schedule[: self.phase_at(env_steps)]):
            if name in e:
                return e[name]
        return default

    def learning_rate_at(self, env_steps: int) -> float:
        """Adam's learning rate at ``env_steps``.

        :attr:`learning_rate`, or a schedule's, times the run's linear decay (``lr_schedule =
        "linear"``: 1 - env_steps / total).
        """
        lr = float(self._scheduled("learning_rate", env_steps, self.learning_rate))
        if self.lr_schedule == "linear":
            lr *= max(0.0, 1.0 - env_steps / max(self.total_timesteps, 1))
        return lr

    def stand_gamma_at(self, env_steps: int) -> float:
        """The standing rows' discount at ``env_steps`` (:attr:`stand_gamma`, or a schedule's)."""
        return float(self._scheduled("stand_gamma", env_steps, self.stand_gamma))

    RESTART_KEYS = ("every", "window", "min_steps", "max")

    def _check_restart(self) -> None:
        """Refuse a ``[restart]`` with a wrong key or value, or a window longer than a period."""
        r = self.restart
        if not r:
            return
        if set(r) != set(self.RESTART_KEYS):
            raise ValueError(f"[restart] takes {', '.join(self.RESTART_KEYS)}, got {sorted(r)}")
        for k in self.RESTART_KEYS:
            v = r[k]
            if isinstance(v, bool) or not isinstance(v, int) or not 0 < v <= 10**9:
                raise ValueError(f"[restart] {k} must be a whole number in [1, 1e9], got {v!r}")
        if r["max"] > MAX_RESTARTS:
            raise ValueError(f"[restart] max must be at most {MAX_RESTARTS}, got {r['max']!r}")
        for name, on in (("teacher", self.teacher), ("init_from", self.init_from),
                         ("critic_warmup", self.critic_warmup > 0)):  # fmt: skip
            if on:
                raise ValueError(f"[restart] draws a random network: not with {name} (its "
                                 f"network does not start random)")  # fmt: skip
        if r["window"] > r["every"]:
            raise ValueError(f"[restart] window ({r['window']}) must be at most every "
                             f"({r['every']}) env steps")  # fmt: skip

    def _check_start_curriculum(self) -> None:
        """Refuse a ``[start_curriculum]`` with a wrong key or start, or a switch never reached."""
        from biped_constraint_env.settings import make_settings, with_start_kind

        c = self.start_curriculum
        if not c:
            return
        if set(c) != {"first", "until_episode_s"}:
            raise ValueError("[start_curriculum] takes first (a start) and until_episode_s [s], "
                             f"got {sorted(c)}")  # fmt: skip
        train = make_settings(**self.train_env_kwargs())
        try:
            with_start_kind(train, c["first"])
        except (ValueError, TypeError) as e:
            raise ValueError(f"[start_curriculum] first: {e}") from None
        longest = self.train_episode_s or train.time_limit_s
        u = c["until_episode_s"]
        if isinstance(u, bool) or not isinstance(u, int | float) or not 0 < u <= (longest or 1e4):
            raise ValueError(f"[start_curriculum] until_episode_s must be in (0, {longest}] s "
                             f"(a training episode lasts at most that), got {u!r}")  # fmt: skip

    def check_untrusted(self) -> None:
        """Refuse what a config from anywhere must not name (a loaded run's config.toml).

        The env id must be the registered one (Gymnasium imports the module of a
        ``"module:Id"`` id); controllers, teachers and references must be the package's own
        names, not paths; a saved config resumes nothing else.
        """
        from training.controller.model_controller import shipped_controllers

        self.validate()
        for name in ("teacher", "base_controller"):
            spec = getattr(self, name)
            if not spec or spec == "model":
                continue
            kind, _, names = spec.partition(":")
            parts = names.split("+") if names else []
            known = shipped_controllers()
            if kind != "model" or not 1 <= len(parts) <= 2 or any(p not in known for p in parts):
                raise ValueError(
                    f"{name} must be '', 'model' or 'model:NAME[+NAME]' with shipped names "
                    f"{known}, got {spec!r}"
                )
        if self.resume:
            raise ValueError(f"resume must be empty in a saved config, got {self.resume!r}")

    def gamma_at(self, env_steps: int) -> float:
        """The discount at ``env_steps`` (:attr:`gamma`, its ramp's or a schedule's)."""
        if self.gamma_final <= 0:
            return float(self._scheduled("gamma", env_steps, self.gamma))
        a, b = self.gamma_ramp
        f = 1.0 if env_steps >= b else 0.0 if env_steps <= a else (env_steps - a) / (b - a)
        return self.gamma + f * (self.gamma_final - self.gamma)

    def env_kwargs(self) -> dict:
        """Keyword arguments of the env the policy runs in: ``[env]``, with its own starts.

        Without the ``"reference"`` start component (reference states are for training): the
        start's other components, or mid-stride where it has none.
        """
        from biped_constraint_env.settings import make_settings
        from biped_constraint_env.starts import split_reference, start_name

        start = make_settings(**self.env).start.start
        weight, own = split_reference(start)
        if weight == 0:
            return dict(self.env)
        return with_keys(self.env, "start", kind=start_name(own or "midstride"))

    def train_env_kwargs(self, env_steps: int = 0) -> dict:
        """Keyword arguments of the training env at ``env_steps``.

        ``[env]``, ``[train_env]`` on top, then the ``train_env`` keys of each ``[[schedule]]``
        entry begun by then.
        """
        kwargs = {**self.env, **self.train_env}
        for e in self.schedule[: self.phase_at(env_steps)]:
            kwargs.update(e.get("train_env", {}))
        return kwargs

    def settings(self):
        """The validated settings of the env the policy runs in (:mod:`biped_constraint_env`)."""
        from biped_constraint_env.settings import make_settings

        return make_settings(**self.env_kwargs())

    def evaluation_start(self) -> str:
        """The start evaluations use: the env's, mid-stride for one trained on both."""
        start = self.settings().start.start
        return start if start in ("rest", "midstride", "stride") else "midstride"

    def train_max_episode_steps(self) -> int | None:
        """The training episodes' time limit in control periods (None: the env's)."""
        if self.train_episode_s <= 0:
            return None
        return max(1, round(self.train_episode_s / self.settings().dt))

    def action_map(self):
        """Policy action -> env action.

        Plain rescaling to torques, a residual on the base controller, or (``action="pd"``)
        the PD targets in [-1, 1] as they are.
        """
        from training.ppo.sb3_vec import ActionMap, action_map_from

        if self.settings().action.unit_actions:  # PD targets in [-1, 1], as they are
            return ActionMap(1.0, None, 1.0)

        gear = self.gear[0] if len(self.gear) == 1 else self.gear
        return action_map_from(self.base_controller, gear)

    def in_the_loop(self) -> str:
        """What acts at run time: the network alone, or with a PD law or a controller."""
        if self.base_controller:
            return f"network residual on the controller {self.base_controller!r}"
        return self.settings().action.in_the_loop()

    def obs_dim(self) -> int:
        """The observation's length (24; + 2 phase entries; + 1 command)."""
        from biped_constraint_env.observation import observation_space

        s = self.settings()
        return observation_space(s.observation.blocks).shape[0]

    def policy_kwargs(self) -> dict:
        """``policy_kwargs`` of SB3's ``MlpPolicy`` for this config.

        With a teacher the network normalises its observations itself
        (:class:`training.ppo.imitation.FixedNormalizer`; the statistics are buffers, set by the
        imitation or by the loaded weights), so that the network alone maps the raw
        observation to its action.
        """
        kw: dict = {
            "net_arch": list(self.net_arch),
            "log_std_init": self.log_std_init,
            "activation_fn": activation_fn(self.activation),
        }
        if self.brake_branch:  # refused without stand_branch (StandBranchPolicy's option)
            kw["brake_branch"] = True
        if self.policy == "experts":
            from training.ppo.experts import check_experts

            kw["experts"] = check_experts(self.experts, self.obs_names())
        if self.teacher:
            from training.ppo.imitation import FixedNormalizer

            n = self.obs_dim()
            kw.update(
                features_extractor_class=FixedNormalizer,
                features_extractor_kwargs={"mean": [0.0] * n, "var": [1.0] * n},
            )
        return kw


ACTIVATIONS = ("tanh", "relu", "elu")

_BIG = 10**12
_RANGES = (  # (field, min, max): every number a config or flag may set
    ("train_episode_s", 0.0, 1e4),
    ("seed", 0, 2**31 - 1), ("total_timesteps", 0, _BIG), ("n_envs", 1, 4096),
    ("env_threads", 1, 256), ("n_steps", 1, 1 << 20), ("batch_size", 1, 1 << 24),
    ("n_epochs", 1, 1000), ("learning_rate", 0.0, 1.0), ("target_kl", 0.0, 10.0),
    ("gamma", 0.0, 1.0), ("gamma_final", 0.0, 1.0), ("gamma_ramp", 0, _BIG),
    ("stand_gamma", 0.0, 1.0),
    ("gae_lambda", 0.0, 1.0), ("clip_range", 0.0, 10.0),
    ("ent_coef", -1.0, 10.0), ("log_std_init", -20.0, 5.0), ("sde_sample_freq", -1, _BIG),
    ("net_arch", 1, 4096), ("torch_threads", 1, 256), ("update_threads", 0, 256),
    ("eval_freq", 1, _BIG), ("eval_episodes", 1, 100_000), ("checkpoint_freq", 1, _BIG),
    ("gear", 1e-6, 1e4), ("bc_episodes0", 0, 1_000_000), ("bc_noise_nm", 0.0, 150.0),
    ("bc_rounds", 0, 10_000), ("bc_episodes", 0, 1_000_000), ("bc_periods0", 1, 1_000_000),
    ("bc_periods", 1, 1_000_000), ("bc_grad_steps", 0, _BIG), ("bc_lr", 0.0, 1.0),
    ("bc_ankle_weight", 0.0, 1e6), ("log_std_joints", -20.0, 5.0), ("action_std_nm", 0.0, 150.0),
    ("stand_std_nm", 0.0, 150.0), ("stand_speed_m_s", 0.0, 10.0), ("action_bias_nm", -150.0, 150.0),
    ("critic_warmup", 0, _BIG), ("bc_anchor_steps", 0, 1_000_000), ("bc_anchor_lr", 0.0, 1.0),
    ("stop_min_steps", 0, 100_000), ("stop_evals", 1, 1000),
    ("stop_confirm_episodes", 0, 100_000),
)  # fmt: skip


def _flag(name: str) -> str:
    return name.replace("_", "-")


def _choices() -> dict[str, tuple]:
    from biped_constraint_env import ENV_ID

    return {
        "env_id": (ENV_ID,),  # the registered id only: "module:Id" would import module
        "vec": ("batched", "subproc", "dummy"),
        "lr_schedule": ("constant", "linear"),
        "select_by": ("mean", "min", "return", "protocol"),
        "init_normalizer": ("snapshot", "fresh"),
        "stand_gamma_rows": ("branch", "zero_command"),
        "learn_rows": ("all", "zero_command"),
        "activation": ACTIVATIONS,
        "policy": ("mlp", "experts"),
    }


def activation_fn(name: str):
    """The torch module class of a hidden activation named in :data:`ACTIVATIONS`."""
    from torch import nn

    classes = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU}
    if name not in classes:
        raise ValueError(f"activation must be one of {ACTIVATIONS}, got {name!r}")
    return classes[name]


TRAIN_SEED_OFFSET = 1_000_000
"""Training episodes draw their starts from seeds ``TRAIN_SEED_OFFSET + seed + i``,
demonstrations from ``DEMO_SEED_OFFSET + ...``, the imitation checks and periodic evaluations
from ``IMITATION_CHECK_SEED_OFFSET`` and ``SELECTION_SEED_OFFSET`` on: never from the final
evaluation's seeds (0, 1, ... in evaluate)."""
DEMO_SEED_OFFSET = 2_000_000
SELECTION_SEED_OFFSET = 10_000
"""Seeds of the periodic evaluations that select ``best/`` (and rank sweep trials)."""
IMITATION_CHECK_SEED_OFFSET = 20_000
"""Seeds of the student episodes that report each imitation round's progress."""
REPORT_SEED_OFFSET = 500_000
"""The report seeds: ``training.evaluation.evaluate``'s default episodes start here. No training
(``TRAIN_SEED_OFFSET``, ``DEMO_SEED_OFFSET``), selection (``SELECTION_SEED_OFFSET``), imitation
check or development choice reads seeds in [500000, 600000)."""
REPORT_EPISODES = 200
"""Episodes per row of a report (a 5% failure rate shows as about 10 failures)."""


def bc_weights(cfg: PPOConfig) -> np.ndarray:
    """Per-joint weights of the cloning error: the stance ankle's, the swing ankle's half."""
    return np.array([cfg.bc_ankle_weight, 1, 1, 1, max(1.0, cfg.bc_ankle_weight / 2)])
