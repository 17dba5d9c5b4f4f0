"""Stable-Baselines3 PPO on ConstrainedBiped-v0, resumable from any interruption.

    python -m training.train_ppo [--config training/configs/ppo_walker.toml] [--flag value ...]
    python -m training.train_ppo --resume runs/train_ppo/<run>   # continue to its saved total
    python -m training.train_ppo --help                          # every setting, explained

Actions are rescaled to [-1, 1] for the policy; observations and rewards are normalised
(VecNormalize; with a teacher the network normalises its observations itself). Several
environments run in one batched compiled call (``--vec batched``, the default) or as SB3
subprocess envs. Threads: torch and the batched env each use one thread by default
(``--torch-threads``, ``--env-threads``): on a 2-core machine, two of each made PPO several
times slower. One seed drives everything.

The run directory holds config.toml, env_settings.json (the validated env settings),
command.txt, versions.json, eval.csv, one
``<start step>.monitor.csv`` per session, tb/ and figures/, and pickle-free snapshots
(:mod:`training.policy_io`): ``imitation/`` (the warm start), ``best/`` (best periodic
evaluation), ``final/`` and ``checkpoints/latest/`` (with the optimiser's state). Every
snapshot is written atomically with the previous one kept; the imitation phase checkpoints
each DAgger round (``checkpoints/imitation/``). ``--resume`` continues whatever was
interrupted, imitation or PPO, to the run's own ``total_timesteps`` (give
``--total-timesteps`` to extend it).
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from biped_constraint_env.actions import TORQUE_LIMIT_NM
from training.plumbing.common import (
    Refusal,
    command,
    given_flags,
    make_run_dir,
    parse_config,
    progress,
    to_toml,
)
from training.plumbing.outputs import OutDir, RunLock, check_tree
from training.plumbing.safe_files import read_csv, read_npz
from training.policy_io import (
    PUBLISHED_FILE,
    STATE_FILE,
    UntrustedFileError,
    available,
    is_complete,
    load_optimizer,
    load_state,
    load_weights,
    open_snapshot,
    policy_batch_actor,
    read_config,
    restore_normalizer,
    save_snapshot,
)
from training.ppo_config import (
    DEMO_SEED_OFFSET,
    IMITATION_CHECK_SEED_OFFSET,
    SELECTION_SEED_OFFSET,
    TRAIN_SEED_OFFSET,
    PPOConfig,
    bc_weights,
)
from training.rollouts import run_episodes, run_episodes_batched

RESUME_OVERRIDES = ("total_timesteps", "progress")
"""The settings a resume may change (given as flags); every other one is the run's own."""
IMITATION_CKPT = "checkpoints/imitation"
"""Snapshot of the imitation phase after each DAgger round (policy, data, round, RNG)."""
PPO_CKPT = "checkpoints/latest"


def _data_spec(cfg: PPOConfig) -> dict:
    """The shapes of a snapshot's labelled data (observations, actions), for :func:`read_npz`."""
    return {"obs": ((None, cfg.obs_dim()), "f"), "act": ((None, 5), "f")}


def _data_budget(cfg: PPOConfig) -> int:
    """Largest labelled-data member [bytes] the config's imitation phase can write (float64).

    Its DART and DAgger episodes' periods times the observation (or the 5 actions).
    """
    samples = cfg.bc_episodes0 * cfg.bc_periods0 + cfg.bc_rounds * cfg.bc_episodes * cfg.bc_periods
    return max(samples, 1) * max(cfg.obs_dim(), 5) * 8


def imitation_warm_start(cfg: PPOConfig, run: Path, make_model):
    """DART demonstrations and DAgger rounds of the teacher, cloned into a new PPO model.

    ``make_model(mean, var)`` builds the PPO model whose policy normalises observations by
    those statistics (of the demonstrations). After every round the phase is checkpointed
    (``checkpoints/imitation``: weights, data, round, RNG state), and a resumed run continues
    from the last complete round with the same result. Writes ``imitation.csv`` (one row per
    round: data size, fit error, steps of 5 student episodes). Returns (model, data).
    """
    import gymnasium as gym

    from training import imitation
    from training.controller.model_controller import controller_from

    env = gym.make(cfg.env_id, **cfg.env_kwargs()).unwrapped
    teacher = controller_from(cfg.teacher, TORQUE_LIMIT_NM)
    gear = cfg.action_map().gear
    rng = np.random.default_rng(cfg.seed)
    ckpt = run / IMITATION_CKPT

    def collect(seed, episodes, periods, desc, student=None):
        bar = lambda seeds: progress(seeds, len(seeds), desc, enabled=cfg.progress)  # noqa: E731
        return imitation.collect(
            env,
            teacher,
            gear,
            list(range(seed, seed + episodes)),
            periods,
            cfg.bc_noise_nm,
            student=student,
            rng=rng,
            progress=bar,
        ).data

    t0 = time.time()
    prev = ckpt.with_name(ckpt.name + ".prev")
    where = ckpt if is_complete(ckpt) else prev if is_complete(prev) else None
    if where is not None:
        model, data, (k0, seed, rows, wall) = _resume_imitation(cfg, where, make_model, rng)
        t0 -= wall
    else:
        seed = DEMO_SEED_OFFSET + 100_000 * cfg.seed
        print(f"imitation: {cfg.bc_episodes0} noisy teacher episodes (DART)", flush=True)
        data = collect(seed, cfg.bc_episodes0, cfg.bc_periods0, "DART episodes")
        seed += cfg.bc_episodes0
        model = make_model(*imitation.obs_statistics(data.obs))
        k0, rows = 0, []
    t_session = time.time()
    for k in range(k0, cfg.bc_rounds + 1):
        done = k - k0  # rounds of this session: their mean time gives the ETA
        per_round = (time.time() - t_session) / max(done, 1)
        eta = f", about {per_round * (cfg.bc_rounds + 1 - k):.0f} s to go" if done else ""
        rows.append(_imitation_round(cfg, model, data, k, gear, eta, t0))
        if k == cfg.bc_rounds:
            break
        student = imitation.student_fn(model.policy)
        data = data + collect(seed, cfg.bc_episodes, cfg.bc_periods, f"DAgger round {k + 1}",
                              student)  # fmt: skip
        seed += cfg.bc_episodes
        state = {"round": k + 1, "seed": seed, "rows": rows, "rng": rng.bit_generator.state,
                 "wall_s": time.time() - t0}  # fmt: skip
        save_snapshot(
            ckpt, model.policy, state, arrays={"data.npz": {"obs": data.obs, "act": data.act}}
        )
    handle = OutDir.open(run, create=False)
    handle.append(
        "training_time.txt",
        f"imitation: {len(data)} labelled env steps, {time.time() - t0:.0f} s wall\n",
    )
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
    handle.write("imitation.csv", buf.getvalue())
    handle.close()
    return model, data


def _resume_imitation(cfg: PPOConfig, where: Path, make_model, rng):
    """(model, data, (round, seed, rows, wall_s)) of an imitation checkpoint; the RNG restored."""
    from training import imitation
    from training.plumbing.safe_files import read_snapshot

    snap = read_snapshot(where)
    st = load_state(snap)
    path = snap.name("state.json")
    k = st.get("round")
    if type(k) is not int or not 1 <= k <= cfg.bc_rounds:
        raise UntrustedFileError(f"{path}: round must be an integer in [1, {cfg.bc_rounds}]")
    seed, rows = st.get("seed"), st.get("rows")
    if type(seed) is not int or not 0 <= seed < 2**62:
        raise UntrustedFileError(f"{path}: seed must be an integer in [0, 2^62)")
    keys = {"round", "samples", "mse", "student_steps", "wall_s"}
    if (
        not isinstance(rows, list)
        or len(rows) != k
        or not all(isinstance(r, dict) and set(r) == keys for r in rows)
    ):
        raise UntrustedFileError(f"{path}: rows must be one table per round done ({k})")
    if "data.npz" not in snap:
        raise UntrustedFileError(f"{snap.name('data.npz')}: missing")
    z = read_npz(snap.name("data.npz"), _data_spec(cfg), data=snap.files["data.npz"],
                 max_bytes=_data_budget(cfg))  # fmt: skip
    data = imitation.Dataset(z["obs"].astype(np.float32), z["act"].astype(np.float32))
    n = cfg.obs_dim()  # the statistics come with the weights
    model = make_model(np.zeros(n), np.ones(n))
    load_weights(model.policy, snap)
    try:
        rng.bit_generator.state = st["rng"]
    except (KeyError, TypeError, ValueError, OverflowError):
        raise UntrustedFileError(f"{path}: rng is not a PCG64 state") from None
    print(f"imitation: resuming at round {k} ({len(data)} samples)", flush=True)
    return model, data, (k, seed, rows, st["wall_s"])


def _imitation_round(cfg: PPOConfig, model, data, k: int, gear, eta: str, t0: float) -> dict:
    """Round ``k``'s fit of the data into the policy, and 5 student episodes: its csv row."""
    from training import imitation

    full = k in (0, cfg.bc_rounds)
    steps = cfg.bc_grad_steps if full else cfg.bc_grad_steps // 3
    epochs = max(1, round(steps * 512 / len(data)))
    print(f"imitation round {k} of {cfg.bc_rounds}: fitting {len(data)} samples, {epochs} "
          f"epochs{eta}", flush=True)  # fmt: skip
    mse = imitation.fit(model.policy, data, epochs, lr=cfg.bc_lr, seed=cfg.seed + k,
                        weights=bc_weights(cfg), log=lambda s: print(s, flush=True))  # fmt: skip
    student = imitation.student_fn(model.policy)
    seeds = range(IMITATION_CHECK_SEED_OFFSET, IMITATION_CHECK_SEED_OFFSET + 5)
    eps = run_episodes(lambda o: np.clip(student(o), -1, 1) * gear, cfg.env_kwargs(), seeds,
                       cfg.env_id)  # fmt: skip
    check = [e["steps_completed"] for e in eps]
    print(f"imitation round {k} of {cfg.bc_rounds}: mse {mse:.2e}, student steps {check} "
          f"({time.time() - t0:.0f} s)", flush=True)  # fmt: skip
    return {"round": k, "samples": len(data), "mse": mse, "student_steps": json.dumps(check),
            "wall_s": round(time.time() - t0)}  # fmt: skip


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


def _progress_bar(cfg: PPOConfig):
    """A bar over the run's whole total: a resumed run starts where it stopped, ETA included."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class RunProgress(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(
                total=cfg.total_timesteps,
                initial=self.model.num_timesteps,
                desc="PPO",
                unit=" env steps",
                unit_scale=True,
                mininterval=1.0,
            )

        def _on_step(self) -> bool:
            self.bar.update(self.model.num_timesteps - self.bar.n)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return RunProgress()


def update_threads(rollout_threads: int, update_threads: int):
    """A callback: torch on ``update_threads`` threads in PPO's updates, else ``rollout_threads``.

    In an update the env is idle, so torch may use the cores the env used in the rollouts
    without the two fighting (the batched env's numba threads are idle, not spinning).
    """
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    class UpdateThreads(BaseCallback):
        def _on_step(self) -> bool:
            return True

        def _on_rollout_start(self) -> None:  # after the previous update
            torch.set_num_threads(rollout_threads)

        def _on_rollout_end(self) -> None:  # the update follows
            torch.set_num_threads(update_threads)

    return UpdateThreads()


def _vecnorm_normalizer(vecnorm):
    """The :class:`~training.policy_io.ObsNormalizer` of a VecNormalize's current statistics."""
    from training.policy_io import ObsNormalizer

    rms = vecnorm.__dict__.get("obs_rms")
    return ObsNormalizer({
        "norm_obs": vecnorm.norm_obs, "obs_mean": getattr(rms, "mean", None),
        "obs_var": getattr(rms, "var", None), "epsilon": vecnorm.epsilon,
        "clip_obs": vecnorm.clip_obs,
    })  # fmt: skip


def _eval_row(eps: list[dict], n: int, wall_s: float) -> dict:
    """One ``eval.csv`` row of a periodic evaluation's episodes."""
    steps = np.array([e["steps_completed"] for e in eps])
    return {
        "env_steps": n,
        "wall_s": round(wall_s, 1),
        "steps_mean": steps.mean(),
        "steps_min": steps.min(),
        "distance_mean_m": float(np.mean([e["distance_m"] for e in eps])),
        "return_mean": float(np.mean([e["return"] for e in eps])),
        "reasons": json.dumps(dict(Counter(e["end"] for e in eps))),
    }


def selection_score(row: dict, select_by: str) -> float:
    """The score of which ``best/`` keeps the highest.

    The mean steps (distance breaks ties), or with ``select_by="min"`` the fewest steps of the
    episodes first.
    """
    score = float(row["steps_mean"] + 1e-3 * row["distance_mean_m"])
    return float(row["steps_min"] + 1e-3 * score) if select_by == "min" else score


def _append_csv(run: OutDir, name: str, row: dict) -> None:
    """Append one row to the run's CSV ``name`` (its header first when the file is new)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(row))
    if run.kind(name) is None:
        w.writeheader()
    w.writerow(row)
    run.append(name, buf.getvalue())


def truncate_eval_csv(run: OutDir, n: int) -> int:
    """Keep the ``eval.csv`` rows of evaluations at or before env step ``n`` (a resume's).

    Evaluations after the checkpoint a resume continues from are redone by it; their rows
    go, so that no row is duplicated. Returns the rows dropped.
    """
    if run.kind("eval.csv") is None:
        return 0
    rows = read_csv(run.path / "eval.csv", {"env_steps": int}, run.path)
    text = run.read_text("eval.csv", 64 << 20)
    lines = text.splitlines(keepends=True)
    keep = [i for i, r in enumerate(rows) if 0 <= r["env_steps"] <= n]
    if len(keep) == len(rows):
        return 0
    if keep != list(range(len(keep))):
        raise UntrustedFileError(f"{run.path / 'eval.csv'}: rows out of env-step order")
    run.write("eval.csv", "".join(lines[: 1 + len(keep)]))
    return len(rows) - len(keep)


def _callbacks(
    cfg: PPOConfig, run: OutDir, vecnorm, best: float, wall0: float = 0.0, streak: int = 0
):
    from stable_baselines3.common.callbacks import BaseCallback

    class EvalAndCheckpoint(BaseCallback):
        """Evaluate (steps, distance, termination reasons) and checkpoint periodically.

        The evaluation runs the deterministic policy on ``cfg.eval_episodes`` selection
        seeds at once in the batched env (:func:`training.rollouts.run_episodes_batched`).

        ``best``: the best score so far (carried over by a resume), so that ``best/`` is
        replaced only by a better evaluation.
        """

        def __init__(self):
            super().__init__()
            self.next_eval = cfg.eval_freq
            self.next_ckpt = cfg.checkpoint_freq
            self.best = best
            self.streak = streak  # consecutive evaluations meeting the stop criterion
            self.stopped = False
            self.t0 = time.time() - wall0  # wall_s counts over every session of the run
            self.snapshots = Path(run.where())  # paths through the run's held descriptor

        def _on_training_start(self) -> None:
            # on resume, count from the restored step count, not from zero
            n = self.model.num_timesteps
            if n == 0 and cfg.teacher:  # the imitation result competes for best/ too
                self._evaluate(0)
            self.next_eval = (n // cfg.eval_freq + 1) * cfg.eval_freq
            self.next_ckpt = (n // cfg.checkpoint_freq + 1) * cfg.checkpoint_freq

        def _on_step(self) -> bool:
            n = self.model.num_timesteps
            if n >= self.next_eval:
                self.next_eval += cfg.eval_freq
                self._evaluate(n)
            if n >= self.next_ckpt:
                self.next_ckpt += cfg.checkpoint_freq
                self.checkpoint()
            return not self.stopped

        def checkpoint(self) -> None:
            """Save the resumable state (weights, optimiser, normaliser, counters)."""
            save_snapshot(
                self.snapshots / PPO_CKPT,
                self.model.policy,
                {
                    "phase": "ppo",
                    "num_timesteps": self.model.num_timesteps,
                    "best": self.best,
                    "wall_s": time.time() - self.t0,
                    "stop_streak": self.streak,
                    "stopped": self.stopped,
                },
                vecnorm,
                optimizer=True,
            )

        def _evaluate(self, n):
            eps = run_episodes_batched(
                policy_batch_actor(self.model.policy, _vecnorm_normalizer(vecnorm), cfg),
                cfg.env_kwargs(),
                range(SELECTION_SEED_OFFSET, SELECTION_SEED_OFFSET + cfg.eval_episodes),
                cfg.env_id,
            )
            row = _eval_row(eps, n, time.time() - self.t0)
            _append_csv(run, "eval.csv", row)
            for k in ("steps_mean", "distance_mean_m", "return_mean"):
                self.logger.record(f"eval/{k}", row[k])
            if cfg.stop_min_steps > 0:
                met = row["steps_min"] >= cfg.stop_min_steps
                self.streak = self.streak + 1 if met else 0
                self.stopped = self.streak >= cfg.stop_evals
            score = selection_score(row, cfg.select_by)
            if score > self.best:
                self.best = score
                save_snapshot(
                    self.snapshots / "best",
                    self.model.policy,
                    {"num_timesteps": n, "score": score, "steps_mean": float(row["steps_mean"])},
                    vecnorm,
                )
            print(
                f"[eval] {n} env steps: steps {row['steps_mean']:.2f} (min {row['steps_min']}), "
                f"distance {row['distance_mean_m']:.2f} m, ends {row['reasons']} "
                f"({time.time() - self.t0:.0f} s)",
                flush=True,
            )
            if self.stopped:
                print(f"[stop] {n} env steps: {stop_reason(cfg)}; the run stops here "
                      f"({time.time() - self.t0:.0f} s)", flush=True)  # fmt: skip

    return EvalAndCheckpoint()


def stop_reason(cfg: PPOConfig) -> str:
    """The stop criterion in words (it held)."""
    return (f"every selection episode completed at least {cfg.stop_min_steps} steps in "
            f"{cfg.stop_evals} consecutive evaluations")  # fmt: skip


def write_settings(run: OutDir, cfg: PPOConfig) -> None:
    """Write ``env_settings.json`` beside config.toml: the validated env settings.

    Those of the env the policy runs in and of the training env (``EnvSettings.as_dict``);
    nothing loads the file.
    """
    from biped_constraint_env.settings import make_settings

    data = {"env": cfg.settings().as_dict(),
            "train_env": make_settings(**cfg.train_env_kwargs()).as_dict()}  # fmt: skip
    run.write("env_settings.json", json.dumps(data, indent=1) + "\n")


def _parse(argv: Sequence[str] | None) -> tuple[PPOConfig, set[str]]:
    """The command line's config and the flags it gives (nothing read from a run yet)."""
    cfg = parse_config(PPOConfig, argv, __doc__.splitlines()[0])
    given = given_flags(PPOConfig, argv) - {"resume", "config", "out_dir"}  # out_dir: the run's
    if cfg.resume:
        ignored = sorted(given - set(RESUME_OVERRIDES))
        if ignored:
            raise Refusal(
                f"train_ppo: error: --resume continues a run with its own settings; only "
                f"{list(RESUME_OVERRIDES)} may be given, not {ignored}"
            )
    return cfg, given


_LOG_NAMES = re.compile(r"[0-9]{1,15}(\.[0-9]{1,6})?\.monitor\.csv")
_TB_RUN = re.compile(r"PPO_[0-9]{1,6}")


def _check_logs(run: OutDir) -> None:
    """Refuse log names that the run does not write (SB3's logger and the figures parse them)."""
    for name in run.names():
        if name.endswith(".monitor.csv") and not _LOG_NAMES.fullmatch(name):
            raise UntrustedFileError(f"{run.path / name}: not a monitor file name this run writes")
    if run.kind("tb") == "dir":
        with run.subdir("tb", create=False) as tb:
            bad = [n for n in tb.names() if not _TB_RUN.fullmatch(n)]
        if bad:
            raise UntrustedFileError(f"{run.path / 'tb' / bad[0]}: not a TensorBoard run name "
                                     f"(PPO_N) this run writes")  # fmt: skip


def _resume_config(flags: PPOConfig, given: set[str], run: OutDir) -> PPOConfig:
    """A resumed run's own config (with the run's lock held and its tree checked).

    A new ``--total-timesteps`` becomes the run's own (its config.toml rewritten through the
    run's descriptor, after the lock: a refused second writer changes nothing).
    """
    try:
        saved = read_config(run.path)
    except FileNotFoundError as e:
        raise Refusal(f"train_ppo: error: --resume: {e}") from None
    cfg = replace(saved, **{k: getattr(flags, k) for k in given}, resume=str(run.path))
    imitation = cfg.teacher and (
        available(run.path, "imitation")
        or is_complete(run.path / IMITATION_CKPT)
        or is_complete(run.path / (IMITATION_CKPT + ".prev"))
    )  # a snapshot the run continues from: a PPO checkpoint, or (a teacher's run) imitation
    if not available(run.path, "checkpoint") and not imitation:
        raise Refusal(
            f"train_ppo: error: --resume: {run.path} has no complete snapshot to continue from "
            f"({PPO_CKPT}, {IMITATION_CKPT} or imitation); start a new run instead"
        )
    if "total_timesteps" in given:  # a new total is the run's own from now on
        run.write("config.toml", to_toml(replace(cfg, resume="")))
    return cfg


def make_model(cfg: PPOConfig, vecnorm, run: Path, mean=None, var=None):
    """The PPO model of a config, with fresh weights.

    ``mean``, ``var``: the statistics of the in-network normaliser (runs with a teacher).
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.utils import LinearSchedule

    policy_kwargs = cfg.policy_kwargs()
    lr = cfg.learning_rate
    if cfg.lr_schedule == "linear":
        lr = LinearSchedule(cfg.learning_rate, 0.0, 1.0)
    if cfg.teacher and mean is not None:
        policy_kwargs["features_extractor_kwargs"] = {"mean": list(mean), "var": list(var)}
    return PPO(
        "MlpPolicy",
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
    )


def training_env(
    cfg: PPOConfig,
    seed: int,
    monitor_file: Path | None = None,
    env_threads=None,
):
    """The training env of a config: (VecMonitor of the SB3 VecEnv, VecNormalize over it).

    The config's training env options (with ``rsi``), its time limit and action map;
    ``env_threads`` overrides
    ``cfg.env_threads``. With a teacher the policy normalises its observations itself (fixed
    statistics), so VecNormalize normalises only the returns.
    """
    from stable_baselines3.common.vec_env import VecNormalize

    venv = _monitored_env(cfg, seed, monitor_file, env_threads)
    vecnorm = VecNormalize(venv, norm_obs=not cfg.teacher, norm_reward=True, gamma=cfg.gamma)
    return venv, vecnorm


def _monitored_env(cfg: PPOConfig, seed: int, monitor_file, env_threads):
    """The config's SB3 VecEnv under a VecMonitor (:func:`training_env`'s inner env)."""
    from stable_baselines3.common.vec_env import VecMonitor

    from training.sb3_vec import make_sb3_vec_env

    venv = make_sb3_vec_env(
        cfg.n_envs,
        seed,
        cfg.train_env_kwargs(),
        cfg.vec,
        cfg.env_id,
        cfg.action_map(),
        num_threads=cfg.env_threads if env_threads is None else env_threads,
        max_episode_steps=cfg.train_max_episode_steps(),
    )
    venv = VecMonitor(
        venv,
        None if monitor_file is None else str(monitor_file),
        info_keywords=("steps_completed", "hip_y", "termination_reason"),
    )
    return venv


def _monitor_file(run: OutDir, start: int) -> Path:
    """A new monitor file of a training session, named by the env step it starts from.

    Created empty here (``O_EXCL``, never through a link), then handed to SB3's monitor as a
    path through the run's descriptor.
    """
    for k in range(1000):
        name = f"{start}.monitor.csv" if k == 0 else f"{start}.{k}.monitor.csv"
        try:
            run.create_new(name)
            return Path(run.where(name))
        except FileExistsError:
            continue
    raise UntrustedFileError(f"{run.path}: 1000 monitor files of step {start} already")


_RUN: list[Path] = []
"""The run directory of the command in progress (for the interrupt message)."""


def _interrupted() -> str:
    if not _RUN:
        return "nothing was written"
    run = _RUN[-1]
    if any(available(run, k) for k in ("checkpoint", "imitation")) or is_complete(
        run / IMITATION_CKPT
    ):
        return f"{run} keeps its last snapshot; continue with: " \
               f"python -m training.train_ppo --resume {run}"  # fmt: skip
    return f"{run} holds no snapshot yet (only its settings); start a new run"


@command("train_ppo", _interrupted)
def main(argv: Sequence[str] | None = None) -> int:
    """Train (or resume) and write the run directory (one writer at a time: a lock).

    A resumed run is untrusted: its lock is taken before anything in it is read or written,
    then its tree is checked (plain files and directories only), then its config is read.
    """
    flags, given = _parse(argv)
    _RUN.clear()
    if flags.resume:
        if not os.path.lexists(flags.resume):
            raise Refusal(f"train_ppo: error: --resume: {flags.resume}: no such directory")
        handle = OutDir.open(Path(flags.resume), create=False)
    else:
        try:
            handle = make_run_dir(flags.out_dir, "train_ppo", flags.env_id, flags.seed, flags,
                                  argv)  # fmt: skip
        except (OSError, UntrustedFileError) as e:
            why = e.strerror if isinstance(e, OSError) else str(e)
            raise Refusal(f"train_ppo: error: --out-dir {flags.out_dir}: cannot create the run "
                          f"({why})") from None  # fmt: skip
    with handle, RunLock(handle):
        _RUN.append(handle.path)
        check_tree(handle)
        _check_logs(handle)
        if flags.resume:
            cfg = _resume_config(flags, given, handle)
        else:
            cfg = flags
            write_settings(handle, cfg)
        return _main(cfg, handle, extend="total_timesteps" in given)


def _main(cfg: PPOConfig, run: OutDir, extend: bool = False) -> int:
    """:func:`main` with the run's lock held."""
    import torch
    from stable_baselines3.common.utils import set_random_seed

    torch.set_num_threads(cfg.torch_threads)
    run.subdir("figures").close()
    print(f"run directory: {run.path}", flush=True)
    set_random_seed(cfg.seed)
    resuming = available(run.path, "checkpoint")
    checkpoint = open_snapshot(run.path, "checkpoint") if resuming else None
    start = load_state(checkpoint)["num_timesteps"] if resuming else 0
    if resuming:
        dropped = truncate_eval_csv(run, start)
        if dropped:
            print(f"eval.csv: {dropped} evaluation(s) after the checkpoint ({start} env steps) "
                  f"will be redone", flush=True)  # fmt: skip
    # one monitor file per session, named by the env step it starts from (never overwritten)
    venv, vecnorm = training_env(cfg, TRAIN_SEED_OFFSET + cfg.seed, _monitor_file(run, start))
    try:
        return _train(cfg, run, venv, vecnorm, checkpoint, extend)
    finally:
        vecnorm.venv.close()


def _train(cfg: PPOConfig, run: OutDir, venv, vecnorm, checkpoint, extend: bool) -> int:
    """The phases of :func:`main` (imitation, PPO, final snapshot) on a prepared env.

    ``checkpoint``: the :class:`~training.plumbing.safe_files.Snapshot` a resume continues
    from (None: a new run); ``extend``: the resume gave a new total (a run that stopped by
    its criterion trains on only then).
    """
    import torch

    fs = Path(run.where())  # the run through its held descriptor: every snapshot written there
    best = -np.inf
    if available(run.path, "best"):
        best = load_state(open_snapshot(run.path, "best")).get("score", -np.inf)
    demos = None
    resuming = checkpoint is not None
    start, streak, stopped = 0, 0, False
    if resuming:
        n = cfg.obs_dim()
        model = make_model(cfg, vecnorm, fs, np.zeros(n), np.ones(n))
        load_weights(model.policy, checkpoint)
        load_optimizer(model.policy, checkpoint)
        restore_normalizer(vecnorm, checkpoint)
        state = load_state(checkpoint)
        model.num_timesteps = start = state["num_timesteps"]
        best = max(best, state.get("best", -np.inf))
        streak = state.get("stop_streak", 0)
        if type(streak) is not int or not 0 <= streak <= 1000:
            raise UntrustedFileError(f"{checkpoint.name(STATE_FILE)}: stop_streak out of range")
        if not isinstance(state.get("stopped", False), bool):
            raise UntrustedFileError(f"{checkpoint.name(STATE_FILE)}: stopped must be a boolean")
        stopped = state.get("stopped", False) and not extend
        print(f"resuming PPO at {model.num_timesteps} of {cfg.total_timesteps} env steps")
    elif cfg.teacher and available(run.path, "imitation"):
        n = cfg.obs_dim()
        model = make_model(cfg, vecnorm, fs, np.zeros(n), np.ones(n))
        load_weights(model.policy, open_snapshot(run.path, "imitation"))
        print("starting PPO from the run's imitation result", flush=True)
    elif cfg.teacher:
        model, demos = imitation_warm_start(
            cfg, fs, lambda mean, var: make_model(cfg, vecnorm, fs, mean, var)
        )
    else:
        model = make_model(cfg, vecnorm, fs)
    if model.num_timesteps == 0:
        if len(cfg.log_std_joints) == 5:
            model.policy.log_std.data[:] = torch.as_tensor(cfg.log_std_joints)
        elif cfg.log_std_joints:
            raise Refusal("train_ppo: error: --log-std-joints needs 5 values (one per joint) "
                          "or none")  # fmt: skip
        if cfg.action_std_nm > 0:
            gear = torch.as_tensor(cfg.action_map().gear, dtype=torch.float32)
            model.policy.log_std.data[:] = torch.log(cfg.action_std_nm / gear)
        if cfg.teacher and not available(run.path, "imitation"):  # the imitation result alone
            arrays = {"demos.npz": {"obs": demos.obs, "act": demos.act}}
            save_snapshot(fs / "imitation", model.policy, {"num_timesteps": 0}, vecnorm,
                          arrays=arrays)  # fmt: skip
    anchor = None
    if cfg.teacher and cfg.bc_anchor_steps > 0:
        from training.imitation import Anchor, Dataset

        snap = open_snapshot(run.path, "imitation")
        if "demos.npz" not in snap:
            raise UntrustedFileError(f"{snap.name('demos.npz')}: missing")
        z = read_npz(snap.name("demos.npz"), _data_spec(cfg), data=snap.files["demos.npz"],
                     max_bytes=_data_budget(cfg))  # fmt: skip
        demos = Dataset(z["obs"].astype(np.float32), z["act"].astype(np.float32))
        anchor = Anchor(
            model.policy, demos, cfg.bc_anchor_lr, weights=bc_weights(cfg), seed=cfg.seed
        )
    remaining = max(cfg.total_timesteps - model.num_timesteps, 0)
    if stopped:
        print(f"the run stopped at {start} env steps: {stop_reason(cfg)}; give "
              f"--total-timesteps to train on", flush=True)  # fmt: skip
        remaining = 0
    t0 = time.time()
    wall0 = load_state(checkpoint).get("wall_s", 0.0) if resuming else 0.0
    callback = _callbacks(cfg, run, vecnorm, best, float(wall0), 0 if extend else streak)
    callback.stopped = stopped
    if remaining > 0:
        print(f"PPO: {remaining} env steps to go", flush=True)
        model.learn(
            total_timesteps=remaining,
            callback=[
                callback,
                _critic_warmup(cfg, anchor),
                update_threads(cfg.torch_threads, cfg.update_threads or cfg.torch_threads),
                *([_progress_bar(cfg)] if cfg.progress else []),
            ],
            reset_num_timesteps=start == 0,
        )
        callback.checkpoint()
    wall = time.time() - t0
    save_snapshot(fs / "final", model.policy, {"num_timesteps": model.num_timesteps}, vecnorm)
    ended = (f"stopped: {stop_reason(cfg)}" if callback.stopped
             else f"the budget of {cfg.total_timesteps} env steps ended")  # fmt: skip
    _publish(cfg, run, ended)
    run.append(
        "training_time.txt",
        f"PPO: {model.num_timesteps} env steps, {wall:.0f} s wall this session; {ended}\n",
    )
    from training.plumbing.plots import learning_curve

    with run.subdir("figures") as figs:
        learning_curve(run.path, Path(figs.where()) / "learning_curve.png")
    print(
        f"done: {model.num_timesteps} env steps in {wall:.0f} s ({ended}); run directory: "
        f"{run.path}",
        flush=True,
    )
    return 0


def _publish(cfg: PPOConfig, run: OutDir, ended: str = "") -> None:
    """Record in ``published.json`` the snapshot the run publishes (``evaluate`` loads it).

    The run's own rule: ``best/``, its best periodic evaluation on the selection seeds, when
    it has one; else ``final/``.
    """
    if available(run.path, "best"):
        st = load_state(open_snapshot(run.path, "best"))
        by = "the fewest steps of" if cfg.select_by == "min" else "the mean steps over"
        why = (
            f"the run's selection: the best score ({by} {cfg.eval_episodes} selection "
            f"episodes, seeds {SELECTION_SEED_OFFSET}+) at {st['num_timesteps']} env steps"
        )
        which = "best"
    else:
        which, why = "final", "the run made no selection evaluation: its last weights"
    if ended:
        why += f" (training: {ended})"
    run.write(PUBLISHED_FILE, json.dumps({"snapshot": which, "why": why}, indent=1) + "\n")


if __name__ == "__main__":
    raise SystemExit(main())
