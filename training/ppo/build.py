"""The PPO model and the training env of a config (what ``train`` and ``bench_ppo`` build)."""

from __future__ import annotations

from pathlib import Path

from training.ppo.config import PPOConfig

OPTIMIZER_KWARGS = {"eps": 1e-5, "foreach": True}
"""The Adam of every run: SB3's own (its ``eps``, 1e-5, which SB3 sets only where no
``optimizer_kwargs`` are given) stepping all parameters at once (torch's multi-tensor
``foreach`` step: the same numbers as the one-tensor-at-a-time default on the CPU, faster;
``tests/test_speed_exact.py`` trains both). None: SB3's default Adam."""


def make_model(cfg: PPOConfig, vecnorm, run: Path, mean=None, var=None):
    """The PPO model of a config, with fresh weights.

    Adam: :data:`OPTIMIZER_KWARGS`.

    ``mean``, ``var``: the statistics of the in-network normaliser (runs with a teacher).
    With ``stand_std_nm`` the policy is :class:`training.ppo.exploration.StandNoisePolicy`
    (the same weights as ``MlpPolicy``; a fixed noise on the rows commanded to stand); with
    ``stand_branch``, :class:`training.ppo.stand_branch.StandBranchPolicy` (with
    ``stand_gamma``, its rows' own discount:
    :class:`training.ppo.stand_branch.BranchDiscountBuffer`).
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.utils import LinearSchedule

    policy_kwargs = cfg.policy_kwargs()
    if OPTIMIZER_KWARGS is not None:
        policy_kwargs["optimizer_kwargs"] = dict(OPTIMIZER_KWARGS)
    policy = "MlpPolicy"
    if cfg.stand_std_nm > 0:
        import numpy as np

        from training.ppo.exploration import StandNoisePolicy

        policy = StandNoisePolicy
        gear = cfg.action_map().gear  # N m per unit action, one per joint
        policy_kwargs["stand_log_std"] = np.log(cfg.stand_std_nm / gear).tolist()
        policy_kwargs["stand_speed"] = cfg.stand_speed_m_s
    elif cfg.stand_branch:
        from training.ppo.stand_branch import StandBranchPolicy

        policy = StandBranchPolicy
    elif cfg.policy == "experts":
        from training.ppo.experts import ExpertsPolicy

        policy = ExpertsPolicy
    # the callback (stand_balance, learn_rows) normalises the advantages, once per rollout
    extra = {"normalize_advantage": False} if cfg.stand_balance or cfg.learn_rows != "all" else {}
    if cfg.stand_gamma > 0:
        from training.ppo.stand_branch import BranchDiscountBuffer

        extra["rollout_buffer_class"] = BranchDiscountBuffer
        entry = cfg.obs_names().index("command_m_s")
        extra["rollout_buffer_kwargs"] = {
            "stand_gamma": cfg.stand_gamma,
            "rows": cfg.stand_gamma_rows,
            "command_entry": entry,
        }
    lr = cfg.learning_rate
    if cfg.lr_schedule == "linear":
        lr = LinearSchedule(cfg.learning_rate, 0.0, 1.0)
    if cfg.teacher and mean is not None:
        policy_kwargs["features_extractor_kwargs"] = {"mean": list(mean), "var": list(var)}
    return PPO(
        policy,
        vecnorm,
        n_steps=cfg.n_steps,
        batch_size=cfg.batch_size,
        n_epochs=cfg.n_epochs,
        learning_rate=lr,
        target_kl=cfg.target_kl if cfg.target_kl > 0 else None,
        use_sde=cfg.use_sde,
        sde_sample_freq=cfg.sde_sample_freq,
        gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda,
        clip_range=cfg.clip_range,
        ent_coef=cfg.ent_coef,
        policy_kwargs=policy_kwargs,
        seed=cfg.seed,
        device="cpu",
        tensorboard_log=str(run / "tb"),
        verbose=0,
        **extra,
    )


def initial_actions(model, cfg: PPOConfig) -> None:
    """The config's initial exploration noise and action bias on a new network (in place).

    ``log_std_joints`` (one log-std per joint) or ``action_std_nm``, and ``action_bias_nm``
    (the action mean's bias, in N m, as the last layer's bias in action units).
    """
    import torch

    p = model.policy
    log_stds = [p.log_std, *getattr(p, "log_stds", ())]  # every expert's (training.ppo.experts)
    heads = [p.action_net, *getattr(p, "heads", ())]
    if len(cfg.log_std_joints) == 5:
        for log_std in log_stds:
            log_std.data[:] = torch.as_tensor(cfg.log_std_joints)
    elif cfg.log_std_joints:
        raise ValueError("--log-std-joints needs 5 values (one per joint) or none")
    gear = torch.as_tensor(cfg.action_map().gear, dtype=torch.float32)
    if cfg.action_std_nm > 0:
        for log_std in log_stds:
            log_std.data[:] = torch.log(cfg.action_std_nm / gear)
    if cfg.action_bias_nm:
        bias = torch.as_tensor(cfg.action_bias_nm, dtype=torch.float32)
        for head in heads:
            head.bias.data[:] = bias / gear


def redraw_network(model, cfg: PPOConfig, seed: int) -> None:
    """The model's network, noise and optimiser as a new run of ``seed`` would draw them.

    The weights of SB3's policy built right after seeding torch with ``seed`` (as
    ``PPO(seed=seed)`` builds it), loaded into the model's own policy; then
    :func:`initial_actions`, and a fresh optimiser. The normaliser, the env and the step count
    go on.
    """
    import torch

    torch.manual_seed(seed)
    p = model.policy
    fresh = model.policy_class(model.observation_space, model.action_space, model.lr_schedule,
                               use_sde=model.use_sde, **model.policy_kwargs)  # fmt: skip
    p.load_state_dict(fresh.state_dict())
    initial_actions(model, cfg)
    if getattr(p, "brake_branch", False):  # a new network's braking actor: its walker's copy
        from training.ppo.stand_branch import copy_walker_to_brake

        copy_walker_to_brake(p)
    p.optimizer = p.optimizer_class(p.parameters(), lr=model.lr_schedule(1.0),
                                    **p.optimizer_kwargs)  # fmt: skip


def training_env(
    cfg: PPOConfig,
    seed: int,
    monitor_file: Path | None = None,
    env_threads=None,
    env_steps: int = 0,
):
    """The training env of a config: (VecMonitor of the SB3 VecEnv, VecNormalize over it).

    The config's training env options at ``env_steps`` (its ``[[schedule]]`` entries begun by
    then; its reference-state starts), its time limit and action map; ``env_threads``
    overrides ``cfg.env_threads``. With a teacher the policy normalises its observations
    itself (fixed statistics), so VecNormalize normalises only the returns. With
    ``stand_std_nm`` or ``stand_branch`` the command and the hip speed are not normalised
    (:func:`training.ppo.exploration.pin_command`); with ``stand_branch_from`` the observation
    statistics stay the start's (the branch's input map is exact for them).
    """
    from training.ppo.sb3_vec import BatchVecNormalize

    venv = monitored_env(cfg, seed, monitor_file, env_threads, env_steps)
    vecnorm = BatchVecNormalize(venv, norm_obs=not cfg.teacher, norm_reward=True, gamma=cfg.gamma)
    if cfg.pins_command:
        from training.ppo.exploration import pin_command

        pin_command(vecnorm, cfg.pinned_entries(), frozen=bool(cfg.stand_branch_from))
    return venv, vecnorm


PHASE_SEED_STRIDE = 10_000
"""The training env of the k-th ``[[schedule]]`` phase draws from seed + k x this (k >= 1;
the first phase from the run's own training seed; at most 64 entries stay below the
demonstrations' seeds)."""


def phase_env(cfg: PPOConfig, seed: int, env_steps: int, env_threads=None):
    """The SB3 VecEnv of the training env in force at ``env_steps`` (no monitor).

    Its rows draw from ``seed`` + :data:`PHASE_SEED_STRIDE` x the phase's number
    (:meth:`PPOConfig.phase_at`).
    """
    from training.ppo.sb3_vec import make_sb3_vec_env

    return make_sb3_vec_env(
        cfg.n_envs,
        seed + PHASE_SEED_STRIDE * cfg.phase_at(env_steps),
        cfg.train_env_kwargs(env_steps),
        cfg.vec,
        cfg.env_id,
        cfg.action_map(),
        num_threads=cfg.env_threads if env_threads is None else env_threads,
        max_episode_steps=cfg.train_max_episode_steps(),
    )


def monitored_env(cfg: PPOConfig, seed: int, monitor_file, env_threads, env_steps: int = 0):
    """The config's SB3 VecEnv under a VecMonitor (:func:`training_env`'s inner env)."""
    from stable_baselines3.common.vec_env import VecMonitor

    venv = VecMonitor(
        phase_env(cfg, seed, env_steps, env_threads),
        None if monitor_file is None else str(monitor_file),
        info_keywords=("steps_completed", "hip_y", "termination_reason"),
    )
    return venv
