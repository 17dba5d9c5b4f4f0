"""The callbacks of a PPO run: selection evaluations, checkpoints, the stop rule, threads.

Stable-Baselines3 ``BaseCallback`` classes built per run by :mod:`training.ppo.train`.
"""

from __future__ import annotations

import csv
import io
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np

from biped_constraint_env.starts import start_name
from training.plumbing.outputs import OutDir
from training.plumbing.rollouts import run_episodes_batched
from training.plumbing.safe_files import read_csv
from training.ppo.config import (
    MAX_RESTARTS,
    SELECTION_SEED_OFFSET,
    PPOConfig,
)
from training.ppo.policy_io import (
    UntrustedFileError,
    policy_batch_actor,
    save_snapshot,
)

PPO_CKPT = "checkpoints/latest"
"""The resumable checkpoint of PPO (weights, optimiser, normaliser, counters)."""


def critic_warmup(cfg: PPOConfig, anchor=None):
    """A callback: the actor frozen for the first ``cfg.critic_warmup`` rollouts.

    The actor: the walker's unless ``walker_frozen`` holds it frozen for the whole run, and a
    standing branch's unless ``stand_branch_frozen`` does
    (:func:`training.ppo.stand_branch.actor_parameters`).
    With ``anchor`` (an :class:`training.ppo.imitation.Anchor`) it also takes
    ``cfg.bc_anchor_steps`` behaviour-cloning steps after every PPO update.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from training.ppo.stand_branch import actor_parameters, brake_parameters, walker_parameters

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
            branch = [] if cfg.stand_branch_frozen else actor_parameters(p)  # frozen: stays so
            walker = [] if cfg.walker_frozen else walker_parameters(p)
            for param in [*walker, *branch, *brake_parameters(p)]:
                param.requires_grad_(not frozen)

    return CriticWarmup()


def gamma_schedule(cfg: PPOConfig, vecnorm):
    """A callback: before every rollout the discounts (and rate) the config gives at that step.

    :meth:`PPOConfig.gamma_at`, set where SB3 reads it: the algorithm (bootstrapping at
    truncation), its rollout buffer (GAE) and the reward normaliser's running return; with a
    standing discount, :meth:`PPOConfig.stand_gamma_at` in the rollout buffer
    (:class:`training.ppo.stand_branch.BranchDiscountBuffer`, which the truncation bootstrap
    reads too); where a ``[[schedule]]`` entry sets a learning rate,
    :meth:`PPOConfig.learning_rate_at` as the model's schedule (SB3 sets Adam's rate from it).
    """
    from stable_baselines3.common.callbacks import BaseCallback

    class GammaSchedule(BaseCallback):
        def _on_step(self) -> bool:
            return True

        def _on_rollout_start(self) -> None:
            t = self.model.num_timesteps
            g = cfg.gamma_at(t)
            buf = self.model.rollout_buffer
            self.model.gamma = buf.gamma = vecnorm.gamma = g
            self.logger.record("train/gamma", g)
            if cfg.stand_gamma > 0:
                buf.stand_gamma = cfg.stand_gamma_at(t)
                self.logger.record("train/stand_gamma", buf.stand_gamma)

        def _on_rollout_end(self) -> None:  # SB3 sets Adam's rate from this before the update
            if lr:  # at the update's step count, as SB3's own schedule reads it
                self.model.lr_schedule = _Constant(cfg.learning_rate_at(self.model.num_timesteps))

    lr = any("learning_rate" in e for e in cfg.schedule)
    return GammaSchedule()


class _Constant:
    """A learning-rate schedule of one value (what SB3 calls with the progress remaining)."""

    def __init__(self, value: float):
        self.value = float(value)

    def __call__(self, _progress_remaining: float) -> float:
        return self.value


def actor_schedule(cfg: PPOConfig, phase: int):
    """A callback: the ``[[schedule]]`` entries' ``copy`` and ``frozen`` on the experts' actors.

    ``frozen``: the list in force (the last entry begun that gives one) holds from the run's
    start in this session and from each entry's first rollout; ``copy``: done once, at the
    first rollout of its entry's phase within a session (a resumed run's weights hold it
    already). ``phase``: the phase the run is in when this session starts.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from training.ppo.experts import copy_actor, set_frozen

    class ActorSchedule(BaseCallback):
        def __init__(self):
            super().__init__()
            self.phase = phase

        def _on_step(self) -> bool:
            return True

        def _on_training_start(self) -> None:
            set_frozen(self.model.policy, cfg._scheduled("frozen", self.model.num_timesteps, ()))

        def _on_rollout_start(self) -> None:
            t = self.model.num_timesteps
            k = cfg.phase_at(t)
            for e in cfg.schedule[self.phase : k]:
                for dst, src in e.get("copy", {}).items():
                    copy_actor(self.model.policy, dst, src)
                    print(f"[schedule] {t} env steps: the {dst} actor starts as a copy of the "
                          f"{src} actor", flush=True)  # fmt: skip
            if k != self.phase:
                set_frozen(self.model.policy, cfg._scheduled("frozen", t, ()))
            self.phase = k

    return ActorSchedule()


def env_schedule(cfg: PPOConfig, vecnorm, seed: int, phase: int):
    """A callback: the training env of each ``[[schedule]]`` phase, from its first rollout.

    Where a phase begins whose training env differs from the one running, before that rollout
    the VecMonitor's env is replaced by the new phase's
    (:func:`training.ppo.build.phase_env`), every row reset there and the model's last
    observation set to the new rows' (normalised by the run's normaliser, whose statistics go
    on); the episodes running end unrecorded. ``seed``: the run's training seed; ``phase``:
    the phase the running env is of.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from training.ppo.build import phase_env

    monitor = vecnorm.venv

    class EnvSchedule(BaseCallback):
        def __init__(self):
            super().__init__()
            self.phase = phase

        def _on_step(self) -> bool:
            return True

        def _on_rollout_start(self) -> None:
            t = self.model.num_timesteps
            k = cfg.phase_at(t)
            if k == self.phase:
                return
            old = cfg.train_env_kwargs(cfg.schedule[self.phase - 1]["at"] if self.phase else 0)
            self.phase = k
            if cfg.train_env_kwargs(t) == old:
                return
            new = phase_env(cfg, seed, t)
            monitor.venv.close()
            monitor.venv = new
            self.model._last_obs = vecnorm.reset()
            self.model._last_episode_starts = np.ones(monitor.num_envs, dtype=bool)
            changed = sorted(cfg.schedule[k - 1].get("train_env", {}))
            print(f"[schedule] {t} env steps: phase {k} begins; the training env's "
                  f"{', '.join(changed)} changed, every row starts again", flush=True)  # fmt: skip
            self.logger.record("train/phase", k)

    return EnvSchedule()


def start_curriculum(cfg: PPOConfig, switched_at: int | None):
    """A callback: the training starts of ``[start_curriculum]`` until the episodes last.

    Training episodes start from its ``first`` start until the mean length of the last 100
    training episodes (SB3's episode buffer) reaches ``until_episode_s``; from the next rollout
    on, from ``[train_env]``'s start (the env's ``set_start``). ``switched_at``: the env step of
    that switch in an earlier session of the run (a resume), else None. Its ``switched_at`` goes
    into every checkpoint.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from biped_constraint_env.settings import make_settings

    c = cfg.start_curriculum
    train = make_settings(**cfg.train_env_kwargs())
    later, dt = start_name(train.start.start), train.dt
    rows = [0] if cfg.vec == "batched" else None  # the batch: one env; SB3's: each env

    class StartCurriculum(BaseCallback):
        def __init__(self):
            super().__init__()
            self.switched_at = switched_at

        def _on_training_start(self) -> None:
            if self.switched_at is None:
                self.training_env.env_method("set_start", c["first"], indices=rows)
                print(f"[starts] training episodes start from {c['first']} until they last "
                      f"{c['until_episode_s']} s on average", flush=True)  # fmt: skip

        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            buf = self.model.ep_info_buffer
            if self.switched_at is not None or buf is None or len(buf) < buf.maxlen:
                return
            mean_s = float(np.mean([e["l"] for e in buf])) * dt
            self.logger.record("train/episode_s", mean_s)
            if mean_s >= c["until_episode_s"]:
                self.switched_at = int(self.model.num_timesteps)
                self.training_env.env_method("set_start", later, indices=rows)
                print(f"[starts] {self.switched_at} env steps: the last {buf.maxlen} training "
                      f"episodes lasted {mean_s:.2f} s on average; training episodes now start "
                      f"from {later}", flush=True)  # fmt: skip

    return StartCurriculum()


RESTART_SEED_STRIDE = 1000
"""The k-th restart draws the network of seed + k x this."""


def check_restarts(restarts, where: str, max_step: int, max_count: int = MAX_RESTARTS):
    """An untrusted checkpoint's ``restarts``, checked.

    Strictly increasing env step counts in [1, ``max_step``], at most ``max_count`` of them
    (else :class:`UntrustedFileError`).
    """
    if (not isinstance(restarts, list) or len(restarts) > max_count
            or any(type(t) is not int or not 1 <= t <= max_step for t in restarts)
            or any(a >= b for a, b in zip(restarts[:-1], restarts[1:], strict=True))):  # fmt: skip
        raise UntrustedFileError(f"{where}: restarts must be the env steps of at most "
                                 f"{max_count} restarts, in order")  # fmt: skip
    return restarts


def check_restart_checked(value, where: str, max_step: int):
    """An untrusted checkpoint's ``restart_checked``: None or an env step count <= max_step."""
    if value is not None and (type(value) is not int or not 0 <= value <= max_step):
        raise UntrustedFileError(f"{where}: restart_checked must be an env step count or null")
    return value


def restart_rule(cfg: PPOConfig, restarts: list[int], checked: int | None = None):
    """A callback: ``[restart]``, a network that has not found the step draws again.

    At every ``every`` env steps (checked after the rollout that reaches it), while fewer than
    ``max`` restarts were made: if the training episodes that ended in the last ``window`` env
    steps completed fewer than ``min_steps`` walking steps in all, the network is drawn again
    (:func:`~training.ppo.build.redraw_network`, seed + RESTART_SEED_STRIDE x k for the k-th).
    The rule reads training episodes only, never an evaluation. A check needs a whole window
    seen by this session: after a resume, a check that was due and not made (``checked``: the
    env step of the last check made, None: none) is made once the session has seen one.
    ``restarts``: the env steps of the restarts so far (a resume's); its ``restarts`` and
    ``checked`` go into every checkpoint.
    """
    from collections import deque

    from stable_baselines3.common.callbacks import BaseCallback

    from training.ppo.build import redraw_network

    r = cfg.restart

    class RestartRule(BaseCallback):
        def __init__(self):
            super().__init__()
            self.restarts = list(restarts)
            self.ends = deque()  # (env step, steps completed) of the episodes that ended
            self.pending = None  # the seed of a network to draw before the next rollout
            self.checked = checked  # the env step of the last check made (None: none)

        def _on_training_start(self) -> None:
            n = self.model.num_timesteps
            self.seen_from = n
            due = (n // r["every"]) * r["every"]  # a check due and not made is made again
            made = self.checked is not None and self.checked >= due
            self.next_check = due + r["every"] if due == 0 or made else due

        def _on_step(self) -> bool:
            dones = self.locals["dones"]
            if dones.any():
                n, infos = self.model.num_timesteps, self.locals["infos"]
                for i in np.flatnonzero(dones):
                    self.ends.append((n, int(infos[i]["steps_completed"])))
            return True

        def steps_in_window(self) -> int:
            """Steps completed by the training episodes that ended in the last window."""
            since = self.model.num_timesteps - r["window"]
            while self.ends and self.ends[0][0] <= since:
                self.ends.popleft()
            return sum(s for _, s in self.ends)

        def _on_rollout_end(self) -> None:
            n = self.model.num_timesteps
            if n < self.next_check or n - self.seen_from < r["window"]:
                return
            self.next_check = (n // r["every"] + 1) * r["every"]
            steps = self.steps_in_window()
            self.logger.record("train/window_steps", steps)
            if len(self.restarts) >= r["max"] or steps >= r["min_steps"]:
                self.checked = int(n)
                return
            self.restarts.append(int(n))
            self.pending = cfg.seed + RESTART_SEED_STRIDE * len(self.restarts)
            self.ends.clear()
            self.seen_from = n
            print(f"[restart] {n} env steps: the training episodes of the last {r['window']} "
                  f"env steps completed {steps} steps (< {r['min_steps']}); restart "
                  f"{len(self.restarts)} of at most {r['max']}: a new network (seed "
                  f"{self.pending}) from the next rollout", flush=True)  # fmt: skip

        def _on_rollout_start(self) -> None:
            # after the update on the last rollout (the old network's own data): the new
            # network collects the next one
            if self.pending is not None:
                redraw_network(self.model, cfg, self.pending)
                if cfg.use_sde:
                    self.model.policy.reset_noise(self.model.n_envs)
                self.pending = None
                self.checked = self.restarts[-1]

        def _on_training_end(self) -> None:
            # training ended before the next rollout: the restart decided was not made (the
            # checkpoint keeps the network it has and the check as not made: a resume makes it)
            if self.pending is not None:
                self.restarts.pop()
                self.pending = None
                print("[restart] training ended before the new network's first rollout: no "
                      "restart made", flush=True)  # fmt: skip

    return RestartRule()


def progress_bar(cfg: PPOConfig):
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
    """The :class:`~training.ppo.policy_io.ObsNormalizer` of a VecNormalize's current statistics."""
    from training.ppo.policy_io import ObsNormalizer

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
    episodes first, or with ``select_by="return"`` the mean return (a task whose reward is
    the measure: following a command, standing at zero).
    """
    if select_by == "protocol":
        return float(row["protocol_score"])
    if select_by == "return":
        return float(row["return_mean"])
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


def make_callbacks(
    cfg: PPOConfig, run: OutDir, vecnorm, best: float, wall0: float = 0.0, streak: int = 0,
    more_state=dict,
):  # fmt: skip
    """The run's evaluation, checkpoint and stop callback.

    ``best``: the best selection score so far; ``wall0``: the run's wall time before this
    session [s]; ``streak``: the evaluations in a row that met the stop criterion;
    ``more_state()``: what else each checkpoint saves (the start curriculum's switch).
    """
    from stable_baselines3.common.callbacks import BaseCallback

    class EvalAndCheckpoint(BaseCallback):
        """Evaluate (steps, distance, termination reasons) and checkpoint periodically.

        The evaluation runs the deterministic policy on ``cfg.eval_episodes`` selection
        seeds at once in the batched env
        (:func:`training.plumbing.rollouts.run_episodes_batched`).

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
                    **more_state(),
                },
                vecnorm,
                optimizer=True,
            )

        def _episodes(self, first: int, count: int) -> list[dict]:
            return run_episodes_batched(
                policy_batch_actor(self.model.policy, _vecnorm_normalizer(vecnorm), cfg),
                cfg.env_kwargs(),
                range(SELECTION_SEED_OFFSET + first, SELECTION_SEED_OFFSET + first + count),
                cfg.env_id,
            )

        def _protocol(self, row: dict) -> bool:
            """The command protocol on the selection seeds: its columns into ``row``; all met?"""
            from training.plumbing import command_protocol as cp

            act = policy_batch_actor(self.model.policy, _vecnorm_normalizer(vecnorm), cfg)
            seeds = range(SELECTION_SEED_OFFSET, SELECTION_SEED_OFFSET + cfg.eval_episodes)
            rows = cp.run_protocol(act, cfg.env_kwargs(), seeds, cfg.env_id)
            met = cp.goals(rows)
            row["protocol_score"] = cp.selection_score(rows)
            row["goals_met"] = f"{sum(met.values())}/{len(met)}"
            figures = {r["row"]: r["success"]["rate"] if "success" in r
                       else r["mean_abs_error_m_s"] for r in rows}  # fmt: skip
            row["protocol"] = json.dumps({k: round(v, 4) if np.isfinite(v) else None
                                          for k, v in figures.items()})  # fmt: skip
            self.logger.record("eval/goals_met", sum(met.values()))
            return all(met.values())

        def _evaluate(self, n):
            eps = self._episodes(0, cfg.eval_episodes)
            if (
                cfg.stop_min_steps > 0
                and cfg.stop_confirm_episodes > 0
                and min(e["steps_completed"] for e in eps) >= cfg.stop_min_steps
            ):  # the same network on the next selection seeds
                eps += self._episodes(cfg.eval_episodes, cfg.stop_confirm_episodes)
            row = _eval_row(eps, n, time.time() - self.t0)
            all_met = self._protocol(row) if cfg.select_by == "protocol" else False
            _append_csv(run, "eval.csv", row)
            for k in ("steps_mean", "distance_mean_m", "return_mean"):
                self.logger.record(f"eval/{k}", row[k])
            if cfg.stop_min_steps > 0 or cfg.select_by == "protocol":
                met = all_met if cfg.select_by == "protocol" else \
                    row["steps_min"] >= cfg.stop_min_steps  # fmt: skip
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
            goals = f", goals {row['goals_met']} {row['protocol']}" if "protocol" in row else ""
            print(
                f"[eval] {n} env steps: steps {row['steps_mean']:.2f} (min {row['steps_min']}), "
                f"distance {row['distance_mean_m']:.2f} m, ends {row['reasons']}{goals} "
                f"({time.time() - self.t0:.0f} s)",
                flush=True,
            )
            if self.stopped:
                print(f"[stop] {n} env steps: {stop_reason(cfg)}; the run stops here "
                      f"({time.time() - self.t0:.0f} s)", flush=True)  # fmt: skip

    return EvalAndCheckpoint()


def stop_reason(cfg: PPOConfig) -> str:
    """The stop criterion in words (it held)."""
    where = (f"{cfg.stop_evals} consecutive evaluations" if cfg.stop_evals > 1
             else "an evaluation")  # fmt: skip
    confirm = (f" ({cfg.eval_episodes} + {cfg.stop_confirm_episodes} episodes of the same "
               "network)" if cfg.stop_confirm_episodes > 0 else "")  # fmt: skip
    if cfg.select_by == "protocol":
        return (f"the command protocol's rows met every goal on {cfg.eval_episodes} selection "
                f"episodes each in {where}")  # fmt: skip
    steps = cfg.stop_min_steps
    return f"every selection episode completed at least {steps} steps in {where}{confirm}"
