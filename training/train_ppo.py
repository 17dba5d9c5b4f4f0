"""Stable-Baselines3 PPO on ConstrainedBiped-v0.

    python -m training.train_ppo [--config training/configs/ppo_default.toml] [--flag value ...]
    python -m training.train_ppo --resume runs/train_ppo/<run>   # continue from its checkpoint

Actions are rescaled to [-1, 1] for the policy; observations and rewards are normalised
(VecNormalize, saved with the model). Several environments run in one batched compiled call
(``--vec batched``) or as SB3 subprocess envs (``--vec subproc``). Torch uses one thread per
process by default: on a 2-core machine, 2 threads next to a busy env process made PPO ~20x
slower. One seed drives everything. The run directory holds config.toml, command.txt,
versions.json, checkpoints/, model.zip, vecnormalize.pkl, monitor.csv, eval.csv and tb/.
"""

from __future__ import annotations

import csv
import json
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from biped_constraint_env.actions import TORQUE_LIMIT_NM
from training.common import make_run_dir, parse_config


@dataclass
class PPOConfig:
    """PPO settings (numbers that differ from SB3's defaults say why)."""

    env_id: str = "ConstrainedBiped-v0"
    task: str = "walk"  # the env's task ("walk" or "paper")
    preset: str = "default"  # the accurate physics; evaluation always uses the same
    seed: int = 0
    total_timesteps: int = 3_000_000
    n_envs: int = 16  # one compiled batch: env stepping stays cheap next to the policy
    vec: str = "batched"  # "batched", "subproc" or "dummy"
    n_steps: int = 256  # x 16 envs = 4096 samples per update
    batch_size: int = 512
    n_epochs: int = 10
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    log_std_init: float = -3.0  # action std 0.05 (7.5 N m): the flat stance foot tolerates only
    # about +-11 N m of ankle moment before an end unloads; SB3's 0 (150 N m) breaks contact at once
    net_arch: tuple[int, ...] = (256, 256)
    torch_threads: int = 1
    eval_freq: int = 100_000  # env steps between evaluations
    eval_episodes: int = 10
    checkpoint_freq: int = 250_000  # env steps between checkpoints
    reset_noise_scale: float = 0.01  # the env's default
    fall_hip_height_m: float = 0.0  # > 0: end episodes when the hip is below it [m] (0 = off)
    forward_reward_weight: float = 1.0  # the env's defaults
    alive_bonus: float = 0.5
    switch_bonus: float = 1.0
    step_bonus: float = 5.0
    ctrl_cost_weight: float = 0.1
    base_controller: str = ""  # "model": learn a residual on the model controller ("" = none)
    gear: tuple[float, ...] = (150.0,)  # N m per unit action, one value or one per joint
    # imitation warm start (teacher "" = none): DART demonstrations of the model controller,
    # DAgger rounds, behaviour cloning into the policy network PPO then trains
    teacher: str = ""  # "model" or "model:GAINS.json": the model controller as the teacher
    bc_episodes0: int = 40  # DART episodes of the teacher (round 0)
    bc_noise_nm: float = 0.4  # std of the torque noise injected into every collected episode
    bc_rounds: int = 10  # DAgger rounds (the student acts, the teacher labels)
    bc_episodes: int = 30  # student episodes per DAgger round
    bc_periods0: int = 2000  # cap on control periods per DART episode (10 s)
    bc_periods: int = 600  # cap per DAgger episode: short, so rounds dwell on the start transient
    bc_grad_steps: int = 20_000  # gradient steps of the first and last fit (a third in between)
    bc_lr: float = 1e-3
    bc_ankle_weight: float = 1.0  # weight of the stance ankle's error (the swing ankle: half)
    action_std_nm: float = 0.0  # > 0: initial action std [N m] on every joint (overrides
    # log_std_init; the std of joint j is action_std_nm / gear_j in action units)
    critic_warmup: int = 0  # rollouts at the start of PPO in which only the critic learns
    bc_anchor_steps: int = 0  # behaviour-cloning steps on the imitation data after each PPO
    # update (kickstarting; 0 = off)
    bc_anchor_lr: float = 1e-4
    out_dir: Path = Path("runs")
    resume: str = ""  # a run directory to continue
    progress: bool = True

    def env_kwargs(self) -> dict:
        """Keyword arguments of the env."""
        return {
            "task": self.task,
            "preset": self.preset,
            "reset_noise_scale": self.reset_noise_scale,
            "step_bonus": self.step_bonus,
            "forward_reward_weight": self.forward_reward_weight,
            "alive_bonus": self.alive_bonus,
            "switch_bonus": self.switch_bonus,
            "ctrl_cost_weight": self.ctrl_cost_weight,
            **({"fall_hip_height_m": self.fall_hip_height_m} if self.fall_hip_height_m > 0 else {}),
        }

    def action_map(self):
        """Policy action -> torque (plain rescaling, or a residual on the base controller)."""
        from training.sb3_vec import action_map_from

        gear = self.gear[0] if len(self.gear) == 1 else self.gear
        return action_map_from(self.base_controller, gear)


TRAIN_SEED_OFFSET = 1_000_000
"""Training episodes draw their starts from seeds ``TRAIN_SEED_OFFSET + seed + i``,
demonstrations from ``DEMO_SEED_OFFSET + ...``, the imitation and periodic evaluations from
20,000 and 10,000 on: never from the final evaluation's seeds (0, 1, ... in evaluate)."""
DEMO_SEED_OFFSET = 2_000_000
SELECTION_SEED_OFFSET = 10_000
"""Seeds of the periodic evaluations that select ``best/`` (and rank sweep trials)."""


def bc_weights(cfg: PPOConfig) -> np.ndarray:
    """Per-joint weights of the cloning error: the stance ankle's, the swing ankle's half."""
    return np.array([cfg.bc_ankle_weight, 1, 1, 1, max(1.0, cfg.bc_ankle_weight / 2)])


def imitation_warm_start(cfg: PPOConfig, run: Path, make_model):
    """DART demonstrations and DAgger rounds of the teacher, cloned into a new PPO model.

    ``make_model(mean, var)`` builds the PPO model whose policy normalises observations by
    those statistics (of the demonstrations). Writes ``imitation.csv`` (one row per round:
    data size, fit error, steps of 5 student episodes) into ``run``; returns the model.
    """
    import gymnasium as gym

    from training import imitation
    from training.evaluate import run_episodes
    from training.model_controller import controller_from

    env = gym.make(cfg.env_id, **cfg.env_kwargs()).unwrapped
    teacher = controller_from(cfg.teacher, TORQUE_LIMIT_NM)
    gear = cfg.action_map().gear
    weights = bc_weights(cfg)
    rng = np.random.default_rng(cfg.seed)
    seed = DEMO_SEED_OFFSET + 100_000 * cfg.seed
    t0 = time.time()
    print(f"imitation: {cfg.bc_episodes0} noisy teacher episodes (DART)", flush=True)
    demo = imitation.collect(
        env,
        teacher,
        gear,
        list(range(seed, seed + cfg.bc_episodes0)),
        cfg.bc_periods0,
        cfg.bc_noise_nm,
        rng=rng,
    )
    seed += cfg.bc_episodes0
    data = demo.data
    model = make_model(*imitation.obs_statistics(data.obs))
    rows = []
    for k in range(cfg.bc_rounds + 1):
        full = k in (0, cfg.bc_rounds)
        steps = cfg.bc_grad_steps if full else cfg.bc_grad_steps // 3
        epochs = max(1, round(steps * 512 / len(data)))
        mse = imitation.fit(
            model.policy, data, epochs, lr=cfg.bc_lr, seed=cfg.seed + k, weights=weights
        )
        student = imitation.student_fn(model.policy)
        check = [
            e["steps_completed"]
            for e in run_episodes(
                lambda o, student=student: np.clip(student(o), -1, 1) * gear,
                cfg.env_kwargs(),
                range(20_000, 20_005),
                cfg.env_id,
            )
        ]
        rows.append(
            {
                "round": k,
                "samples": len(data),
                "mse": mse,
                "student_steps": json.dumps(check),
                "wall_s": round(time.time() - t0),
            }
        )
        print(
            f"imitation round {k}: {len(data)} samples, mse {mse:.2e}, student steps "
            f"{check} ({time.time() - t0:.0f} s)",
            flush=True,
        )
        if k == cfg.bc_rounds:
            break
        more = imitation.collect(
            env,
            teacher,
            gear,
            list(range(seed, seed + cfg.bc_episodes)),
            cfg.bc_periods,
            cfg.bc_noise_nm,
            student=student,
            rng=rng,
        )
        seed += cfg.bc_episodes
        data = data + more.data
    with open(run / "training_time.txt", "a") as fh:
        fh.write(f"imitation: {len(data)} labelled env steps, {time.time() - t0:.0f} s wall\n")
    with open(run / "imitation.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return model, data


def _critic_warmup(cfg: PPOConfig, anchor=None):
    """A callback: the actor frozen for the first ``cfg.critic_warmup`` rollouts.

    With ``anchor`` (an :class:`training.imitation.Anchor`) it also takes
    ``cfg.bc_anchor_steps`` behaviour-cloning steps after every PPO update.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    class CriticWarmup(BaseCallback):
        def __init__(self):
            super().__init__()
            self.rollouts = 0

        def _on_step(self) -> bool:
            return True

        def _on_training_start(self) -> None:
            if self.model.num_timesteps > 0:  # resumed: the warm-up is over
                self.rollouts = cfg.critic_warmup

        def _on_rollout_start(self) -> None:  # after the previous rollout's update
            if anchor is not None and self.rollouts > cfg.critic_warmup:
                self.logger.record("train/bc_anchor_mse", anchor.steps(cfg.bc_anchor_steps))

        def _on_rollout_end(self) -> None:
            self.rollouts += 1
            p = self.model.policy
            frozen = self.rollouts <= cfg.critic_warmup
            for param in [
                *p.mlp_extractor.policy_net.parameters(),
                *p.action_net.parameters(),
                p.log_std,
            ]:
                param.requires_grad_(not frozen)

    return CriticWarmup()


def save(model, vecnorm, where: Path) -> None:
    """Write model.zip, vecnormalize.pkl and num_timesteps.txt into ``where``."""
    where.mkdir(exist_ok=True)
    model.save(where / "model.zip")
    vecnorm.save(str(where / "vecnormalize.pkl"))
    (where / "num_timesteps.txt").write_text(str(model.num_timesteps))


def _callbacks(cfg: PPOConfig, run: Path, vecnorm):
    from stable_baselines3.common.callbacks import BaseCallback

    class EvalAndCheckpoint(BaseCallback):
        """Evaluate (steps, distance, termination reasons) and checkpoint periodically."""

        def __init__(self):
            super().__init__()
            self.next_eval = cfg.eval_freq
            self.next_ckpt = cfg.checkpoint_freq
            self.best = -np.inf
            self.t0 = time.time()
            self.csv = run / "eval.csv"

        def _on_training_start(self) -> None:
            # on resume, count from the restored step count, not from zero
            n = self.model.num_timesteps
            if n == 0 and cfg.teacher:  # the imitation result competes for best/ too
                self._evaluate(0)
            self.next_eval = (n // cfg.eval_freq + 1) * cfg.eval_freq
            self.next_ckpt = (n // cfg.checkpoint_freq + 1) * cfg.checkpoint_freq

        def _on_step(self) -> bool:
            n = self.model.num_timesteps
            if n >= self.next_ckpt:
                self.next_ckpt += cfg.checkpoint_freq
                self._save(run / "checkpoints")
            if n >= self.next_eval:
                self.next_eval += cfg.eval_freq
                self._evaluate(n)
            return True

        def _save(self, where: Path):
            save(self.model, vecnorm, where)

        def _evaluate(self, n):
            from training.evaluate import policy_actor, run_episodes

            actor = policy_actor(self.model, vecnorm, cfg)
            eps = run_episodes(
                actor,
                cfg.env_kwargs(),
                range(SELECTION_SEED_OFFSET, SELECTION_SEED_OFFSET + cfg.eval_episodes),
                cfg.env_id,
            )
            steps = np.array([e["steps_completed"] for e in eps])
            dist = np.array([e["distance_m"] for e in eps])
            ret = np.array([e["return"] for e in eps])
            reasons = Counter(e["end"] for e in eps)
            row = {
                "env_steps": n,
                "wall_s": round(time.time() - self.t0, 1),
                "steps_mean": steps.mean(),
                "steps_min": steps.min(),
                "distance_mean_m": dist.mean(),
                "return_mean": ret.mean(),
                "reasons": json.dumps(dict(reasons)),
            }
            new = not self.csv.exists()
            with open(self.csv, "a", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=list(row))
                if new:
                    w.writeheader()
                w.writerow(row)
            for k in ("steps_mean", "distance_mean_m", "return_mean"):
                self.logger.record(f"eval/{k}", row[k])
            score = steps.mean() + 1e-3 * dist.mean()
            if score > self.best:
                self.best = score
                self._save(run / "best")
            print(
                f"[eval] {n} env steps: steps {steps.mean():.2f} (min {steps.min()}), "
                f"distance {dist.mean():.2f} m, ends {dict(reasons)}",
                flush=True,
            )

        def _on_training_end(self) -> None:
            self._save(run / "checkpoints")

    return EvalAndCheckpoint()


def main(argv: Sequence[str] | None = None) -> int:
    """Train (or resume) and write the run directory."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from training.sb3_vec import make_sb3_vec_env

    cfg = parse_config(PPOConfig, argv, __doc__.splitlines()[0])
    torch.set_num_threads(cfg.torch_threads)
    if cfg.resume:
        run = Path(cfg.resume)
        saved = parse_config(PPOConfig, ["--config", str(run / "config.toml")], "")
        overrides = {
            f.name: getattr(cfg, f.name)
            for f in fields(cfg)
            if f.name in ("total_timesteps", "progress")
        }
        cfg = PPOConfig(
            **{
                **{f.name: getattr(saved, f.name) for f in fields(saved)},
                **overrides,
                "resume": str(run),
            }
        )
    else:
        run = make_run_dir(cfg.out_dir, "train_ppo", cfg.env_id, cfg.seed, cfg, argv)
    (run / "figures").mkdir(exist_ok=True)
    print(f"run directory: {run}", flush=True)
    set_random_seed(cfg.seed)
    venv = make_sb3_vec_env(
        cfg.n_envs,
        TRAIN_SEED_OFFSET + cfg.seed,
        cfg.env_kwargs(),
        cfg.vec,
        cfg.env_id,
        cfg.action_map(),
    )
    start = 0
    if cfg.resume:
        start = int((run / "checkpoints" / "num_timesteps.txt").read_text())
    # a resumed session writes its own monitor file, named by the step count it starts from
    monitor = run / ("monitor.csv" if start == 0 else f"monitor.{start}.csv")
    venv = VecMonitor(
        venv, str(monitor), info_keywords=("steps_completed", "hip_y", "termination_reason")
    )
    demos = None
    if cfg.resume:
        vecnorm = VecNormalize.load(str(run / "checkpoints" / "vecnormalize.pkl"), venv)
        model = PPO.load(run / "checkpoints" / "model.zip", env=vecnorm, device="cpu")
        print(f"resuming at {model.num_timesteps} env steps", flush=True)
    else:
        # with a teacher the policy normalises observations itself (fixed statistics)
        vecnorm = VecNormalize(venv, norm_obs=not cfg.teacher, norm_reward=True, gamma=cfg.gamma)

        def make_model(mean=None, var=None):
            policy_kwargs = {"net_arch": list(cfg.net_arch), "log_std_init": cfg.log_std_init}
            if mean is not None:
                from training.imitation import FixedNormalizer

                policy_kwargs.update(
                    features_extractor_class=FixedNormalizer,
                    features_extractor_kwargs={"mean": mean.tolist(), "var": var.tolist()},
                )
            return PPO(
                "MlpPolicy",
                vecnorm,
                n_steps=cfg.n_steps,
                batch_size=cfg.batch_size,
                n_epochs=cfg.n_epochs,
                learning_rate=cfg.learning_rate,
                gamma=cfg.gamma,
                gae_lambda=cfg.gae_lambda,
                clip_range=cfg.clip_range,
                ent_coef=cfg.ent_coef,
                policy_kwargs=policy_kwargs,
                seed=cfg.seed,
                device="cpu",
                tensorboard_log=str(run / "tb"),
                verbose=0,
            )

        if cfg.teacher:
            model, demos = imitation_warm_start(cfg, run, make_model)
        else:
            model = make_model()
        if cfg.action_std_nm > 0:
            gear = torch.as_tensor(cfg.action_map().gear, dtype=torch.float32)
            model.policy.log_std.data[:] = torch.log(cfg.action_std_nm / gear)
        if cfg.teacher:  # the imitation result alone, for comparison
            save(model, vecnorm, run / "imitation")
    anchor = None
    if cfg.teacher and cfg.bc_anchor_steps > 0:
        from training.imitation import Anchor, Dataset

        path = run / "imitation" / "demos.npz"
        if demos is not None:
            np.savez_compressed(path, obs=demos.obs, act=demos.act)
        with np.load(path) as z:
            demos = Dataset(z["obs"], z["act"])
        anchor = Anchor(
            model.policy, demos, cfg.bc_anchor_lr, weights=bc_weights(cfg), seed=cfg.seed
        )
    remaining = max(cfg.total_timesteps - model.num_timesteps, 0)
    t0 = time.time()
    model.learn(
        total_timesteps=remaining,
        callback=[_callbacks(cfg, run, vecnorm), _critic_warmup(cfg, anchor)],
        progress_bar=cfg.progress,
        reset_num_timesteps=not cfg.resume,
    )
    wall = time.time() - t0
    model.save(run / "model.zip")
    vecnorm.save(str(run / "vecnormalize.pkl"))
    with open(run / "training_time.txt", "a") as fh:
        fh.write(f"PPO: {model.num_timesteps} env steps, {wall:.0f} s wall this session\n")
    from training.plots import learning_curve

    learning_curve(run, run / "figures" / "learning_curve.png")
    print(
        f"done: {model.num_timesteps} env steps in {wall:.0f} s; run directory: {run}", flush=True
    )
    venv.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
