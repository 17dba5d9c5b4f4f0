"""A run directory's files besides its snapshots: settings, resume, logs, the published snapshot.

What :mod:`training.ppo.train` reads from and writes into a run directory, every write
through the run's held descriptor (:class:`~training.plumbing.outputs.OutDir`).
"""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

from training.plumbing.common import (
    Refusal,
    to_toml,
)
from training.plumbing.outputs import OutDir
from training.ppo.callbacks import PPO_CKPT
from training.ppo.config import (
    SELECTION_SEED_OFFSET,
    PPOConfig,
)
from training.ppo.policy_io import (
    PUBLISHED_FILE,
    UntrustedFileError,
    available,
    is_complete,
    load_state,
    open_snapshot,
    read_config,
)
from training.ppo.warm_start import IMITATION_CKPT

RESUME_OVERRIDES = ("total_timesteps", "progress")
"""The settings a resume may change (given as flags); every other one is the run's own."""


def write_settings(run: OutDir, cfg: PPOConfig) -> None:
    """Write ``env_settings.json`` beside config.toml: the validated env settings.

    Those of the env the policy runs in and of the training env (``EnvSettings.as_dict``);
    nothing loads the file.
    """
    from biped_constraint_env.settings import make_settings

    data = {"env": cfg.settings().as_dict(),
            "train_env": make_settings(**cfg.train_env_kwargs()).as_dict()}  # fmt: skip
    run.write("env_settings.json", json.dumps(data, indent=1) + "\n")


_LOG_NAMES = re.compile(r"[0-9]{1,15}(\.[0-9]{1,6})?\.monitor\.csv")
_TB_RUN = re.compile(r"PPO_[0-9]{1,6}")


def check_logs(run: OutDir) -> None:
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


def resume_config(flags: PPOConfig, given: set[str], run: OutDir) -> PPOConfig:
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


def new_monitor_file(run: OutDir, start: int) -> Path:
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


def publish(cfg: PPOConfig, run: OutDir, ended: str = "") -> None:
    """Record in ``published.json`` the snapshot the run publishes (``evaluate`` loads it).

    The run's own rule: ``best/``, its best periodic evaluation on the selection seeds, when
    it has one; else ``final/``.
    """
    if available(run.path, "best"):
        st = load_state(open_snapshot(run.path, "best"))
        by = {"min": "the fewest steps of", "return": "the mean return over",
              "protocol": "the command protocol's goals met (then how close it came to the "
                          "rest) on"}.get(cfg.select_by, "the mean steps over")  # fmt: skip
        more = (f", {cfg.stop_confirm_episodes} more where all met the stop criterion"
                if cfg.stop_confirm_episodes > 0 and cfg.stop_min_steps > 0 else "")  # fmt: skip
        why = (
            f"the run's selection: the best score ({by} {cfg.eval_episodes} selection "
            f"episodes{more}, seeds {SELECTION_SEED_OFFSET}+) at {st['num_timesteps']} env steps"
        )
        which = "best"
    else:
        which, why = "final", "the run made no selection evaluation: its last weights"
    if ended:
        why += f" (training: {ended})"
    run.write(PUBLISHED_FILE, json.dumps({"snapshot": which, "why": why}, indent=1) + "\n")
