"""Stable-Baselines3 PPO on ConstrainedBiped-v0, resumable from any interruption.

    python -m training.ppo.train [--config training/configs/ppo_walker.toml] [--flag value ...]
    python -m training.ppo.train --resume runs/train_ppo/RUN   # continue to its saved total
    python -m training.ppo.train --help                          # every setting, explained

Actions are rescaled to [-1, 1] for the policy; observations and rewards are normalised
(VecNormalize; with a teacher the network normalises its observations itself). Several
environments run in one batched compiled call (``--vec batched``, the default) or as SB3
subprocess envs. Threads: torch and the batched env each use one thread by default
(``--torch-threads``, ``--env-threads``): on a 2-core machine, two of each made PPO several
times slower. One seed drives everything.

The run directory holds config.toml, env_settings.json (the validated env settings),
command.txt, versions.json, eval.csv, one
``<start step>.monitor.csv`` per session, tb/ and figures/, and pickle-free snapshots
(:mod:`training.ppo.policy_io`): ``imitation/`` (the warm start), ``best/`` (best periodic
evaluation), ``final/`` and ``checkpoints/latest/`` (with the optimiser's state). Every
snapshot is written atomically with the previous one kept; the imitation phase checkpoints
each DAgger round (``checkpoints/imitation/``). ``--resume`` continues whatever was
interrupted, imitation or PPO, to the run's own ``total_timesteps`` (give
``--total-timesteps`` to extend it).
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from training.plumbing.common import (
    Refusal,
    command,
    given_flags,
    make_run_dir,
    parse_config,
)
from training.plumbing.outputs import OutDir, RunLock, check_tree
from training.plumbing.safe_files import read_npz
from training.ppo.build import initial_actions, make_model, training_env
from training.ppo.callbacks import (
    actor_schedule,
    check_restart_checked,
    check_restarts,
    critic_warmup,
    env_schedule,
    gamma_schedule,
    make_callbacks,
    progress_bar,
    restart_rule,
    start_curriculum,
    stop_reason,
    truncate_eval_csv,
    update_threads,
)
from training.ppo.config import (
    TRAIN_SEED_OFFSET,
    PPOConfig,
    bc_weights,
)
from training.ppo.policy_io import (
    NORMALIZER_FILE,
    POLICY_FILE,
    STATE_FILE,
    UntrustedFileError,
    available,
    build_policy,
    check_weights,
    is_complete,
    json_text,
    load_optimizer,
    load_state,
    load_weights,
    open_policy,
    open_snapshot,
    published_snapshot,
    read_config,
    read_normalizer,
    restore_normalizer,
    save_snapshot,
)
from training.ppo.runs import (
    RESUME_OVERRIDES,
    check_logs,
    new_monitor_file,
    publish,
    resume_config,
    write_settings,
)
from training.ppo.warm_start import IMITATION_CKPT, data_budget, data_spec, imitation_warm_start


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
               f"python -m training.ppo.train --resume {run}"  # fmt: skip
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
                                  argv, module="training.ppo.train")  # fmt: skip
        except (OSError, UntrustedFileError) as e:
            why = e.strerror if isinstance(e, OSError) else str(e)
            raise Refusal(f"train_ppo: error: --out-dir {flags.out_dir}: cannot create the run "
                          f"({why})") from None  # fmt: skip
    with handle, RunLock(handle):
        _RUN.append(handle.path)
        check_tree(handle)
        check_logs(handle)
        if flags.resume:
            cfg = resume_config(flags, given, handle)
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
    venv, vecnorm = training_env(cfg, TRAIN_SEED_OFFSET + cfg.seed, new_monitor_file(run, start),
                                 env_steps=start)  # fmt: skip
    try:
        return _train(cfg, run, venv, vecnorm, checkpoint, extend)
    finally:
        vecnorm.venv.close()


def _start_from(cfg: PPOConfig, run: OutDir, vecnorm, fs: Path):
    """A new run's model from ``cfg.init_from``'s published snapshot (a second stage).

    Its weights and its normaliser, checked as any untrusted snapshot (the config's initial
    exploration noise, where it sets one, then replaces the snapshot's action std; with
    ``init_normalizer = "fresh"`` the run's normaliser starts anew instead); the run records
    where it started (``init_from.json``: the policy, its snapshot, the weights' SHA-256 and
    which normaliser).
    """
    src = Path(cfg.init_from)
    if not src.is_dir():
        raise Refusal(f"train_ppo: error: --init-from: {src}: no such policy directory")
    which, _ = published_snapshot(src)
    snap = original = open_snapshot(src, which)
    added = _added_entries(src, cfg)
    if added:
        from training.ppo.widen import widen_snapshot

        statistics = (
            _added_statistics(cfg, added)
            if cfg.init_normalizer == "snapshot"
            else (np.zeros(len(added)), np.ones(len(added)))
        )  # fresh: not read
        try:
            snap = widen_snapshot(snap, added, *statistics, width=cfg.obs_dim() - len(added))
        except ValueError as e:
            raise Refusal(f"train_ppo: error: --init-from: {e}") from None
        print(f"the start's network widened with zero columns for observation entries "
              f"{added}", flush=True)  # fmt: skip
    check_weights(cfg, snap)
    start = _start_config(src)
    if start is not None and start.stand_branch and not cfg.stand_branch:
        raise Refusal(f"train_ppo: error: --init-from: {src}'s network has a standing branch; "
                      f"give --stand-branch to this run too")  # fmt: skip
    model = make_model(cfg, vecnorm, fs)
    _load_start(cfg, start, snap, model.policy)
    if cfg.pins_command:
        _command_in_m_s(src, snap, cfg, model.policy)
    elif start is not None and start.pins_command:
        raise Refusal(f"train_ppo: error: --init-from: {src} was trained with --stand-std-nm "
                      f"or --stand-branch: its network reads the command and the hip speed in "
                      f"m/s; give one of them to this run too")  # fmt: skip
    if cfg.init_normalizer == "snapshot":
        restore_normalizer(vecnorm, snap)
    digest = hashlib.sha256(original.files[POLICY_FILE]).hexdigest()
    record = {"policy": str(src), "snapshot": which, "policy_sha256": digest,
              "normalizer": cfg.init_normalizer, "added_inputs": added}  # fmt: skip
    if cfg.stand_branch_from:
        record["stand_branch_from"] = _branch_start(cfg, vecnorm, model.policy)
    run.write("init_from.json", json_text(record))
    print(f"starting PPO from {src} ({which}/, weights sha256 {digest[:12]}, "
          f"{cfg.init_normalizer} normaliser)", flush=True)  # fmt: skip
    return model


def _added_entries(src: Path, cfg: PPOConfig) -> list[int]:
    """The observation entries this run adds to its start's (``training.ppo.widen``).

    None where the start's config observes the same blocks, or where the start has no config.
    """
    from training.ppo.widen import added_entries

    try:
        old = read_config(src).settings().observation.blocks
    except FileNotFoundError:
        return []
    new = cfg.settings().observation.blocks
    if old == new:
        return []
    try:
        return added_entries(old, new)
    except ValueError as e:
        raise Refusal(f"train_ppo: error: --init-from: {src}: {e}") from None


ADDED_STATISTICS_SEED = 900_000
"""The seeds (+ the run's seed) of the resets that give added inputs their first statistics:
a range no protocol reads (report 500000+, development 700000+, selection 10000+)."""


def _added_statistics(cfg: PPOConfig, added: list[int], resets: int = 16):
    """The mean and variance of the ``added`` entries over ``resets`` x n_envs start states.

    From a separate instance of the run's training env (its own seeds,
    :data:`ADDED_STATISTICS_SEED`), so the run's own draws are untouched; a variance floor of
    1e-6 keeps an entry constant over the starts finite.
    """
    from training.ppo.build import monitored_env

    venv = monitored_env(cfg, ADDED_STATISTICS_SEED + cfg.seed, None, 1)
    try:
        obs = np.concatenate([venv.reset() for _ in range(resets)])[:, added]
    finally:
        venv.close()
    return obs.mean(axis=0), np.maximum(obs.var(axis=0), 1e-6)


def _start_config(src: Path):
    """The start's config (None where the policy directory has none)."""
    try:
        return read_config(src)
    except FileNotFoundError:
        return None


def _load_start(cfg: PPOConfig, start, snap, policy) -> None:
    """Load the start's weights into ``policy``; a plain actor into a standing-branch run's.

    ``start``: the start's config (None: it has none). A ``stand_branch`` run from a start
    without one takes the start's walker (every weight an ``MlpPolicy`` has) and keeps its
    branch as built (random, or then from ``stand_branch_from``). A ``brake_branch`` run from a
    start without a braking actor gets its copy of the walker later (:func:`_start_brake`).
    """
    has_brake = start is not None and start.brake_branch
    if has_brake and not cfg.brake_branch:
        raise Refusal("train_ppo: error: --init-from: the start's network has a braking "
                      "actor; give --brake-branch to this run too")  # fmt: skip
    has_branch = start is not None and start.stand_branch
    added = (() if has_branch or not cfg.stand_branch else ("branch_",)) + (
        () if has_brake or not cfg.brake_branch else ("brake_",))  # fmt: skip
    if not added:
        load_weights(policy, snap)
        return
    from dataclasses import replace

    # the start's own network (its parts only), loaded, then into this run's
    shape = build_policy(replace(cfg, stand_branch=has_branch, stand_branch_from="",
                                 brake_branch=False))  # fmt: skip
    load_weights(shape, snap)
    missing, unexpected = policy.load_state_dict(shape.state_dict(), strict=False)
    assert not unexpected and all(k.startswith(added) for k in missing), missing


def _start_brake(cfg: PPOConfig, policy) -> None:
    """A new ``brake_branch`` run's braking actor: the walker's copy, unless its start had one.

    Called once the walker is as the run starts it (loaded, its pinned inputs folded into the
    first layer, the config's initial noise and bias set), so the copy acts as the walker does.
    """
    if not cfg.brake_branch:
        return
    start = _start_config(Path(cfg.init_from)) if cfg.init_from else None
    if start is None or not start.brake_branch:
        from training.ppo.stand_branch import copy_walker_to_brake

        copy_walker_to_brake(policy)


def _branch_source(path: Path):
    """(policy, normaliser dict, snapshot name, weights' SHA-256) of a policy directory.

    Its published snapshot, read once and checked as any loaded policy
    (:func:`~training.ppo.policy_io.open_policy`): a plain actor with observation statistics.
    """
    which, _ = published_snapshot(path)
    policy, stats, cfg, _, snap = open_policy(path, which)
    if cfg.stand_branch:
        raise ValueError(f"{path} has a standing branch itself: give a plain actor")
    if stats is None:
        raise ValueError(f"{path}: its network normalises its own input (no statistics to map)")
    return policy, stats, which, hashlib.sha256(snap.files[POLICY_FILE]).hexdigest()


def _branch_start(cfg: PPOConfig, vecnorm, policy) -> dict:
    """Start the branch from ``cfg.stand_branch_from``'s actor; (where, its weights' SHA-256)."""
    from training.ppo.stand_branch import branch_from

    src = Path(cfg.stand_branch_from)
    if not src.is_dir():
        raise Refusal(f"train_ppo: error: --stand-branch-from: {src}: no such policy directory")
    try:
        source, norm, which, digest = _branch_source(src)
        stats = vecnorm.obs_rms
        branch_from(policy, source, norm, stats.mean, stats.var, vecnorm.epsilon,
                    float(vecnorm.ret_rms.var))  # fmt: skip
    except ValueError as e:
        raise Refusal(f"train_ppo: error: --stand-branch-from: {e}") from None
    print(f"the standing branch starts from {src} ({which}/, weights sha256 {digest[:12]})",
          flush=True)  # fmt: skip
    return {"policy": str(src), "snapshot": which, "policy_sha256": digest}


def _command_in_m_s(src: Path, snap, cfg: PPOConfig, policy) -> None:
    """A start made to read the command and hip speed in m/s (in place; ``cfg.pins_command``).

    Such a run feeds the network those entries unnormalised (mean 0, variance 1 in its
    normaliser); a start whose normaliser held other statistics for them has them folded into
    its first layers, exactly (:func:`training.ppo.exploration.fold_pinned_inputs`), or is
    refused where its input was clipped.
    """
    from training.ppo.exploration import fold_pinned_inputs

    raw = snap.files.get(NORMALIZER_FILE)
    if raw is None:
        raise UntrustedFileError(f"{snap.name(NORMALIZER_FILE)}: missing")
    d = read_normalizer(snap.name(NORMALIZER_FILE), cfg.obs_dim(), raw)
    if not d["norm_obs"]:
        raise UntrustedFileError(f"{snap.name(NORMALIZER_FILE)}: holds no observation statistics")
    try:
        exact = cfg.init_normalizer == "snapshot"  # a fresh one keeps nothing exactly
        folded = fold_pinned_inputs(policy, d["obs_mean"], d["obs_var"], d["epsilon"],
                                    d["clip_obs"], exact=exact)  # fmt: skip
    except ValueError as e:
        raise Refusal(f"train_ppo: error: this run feeds the network the command and the "
                      f"hip speed in m/s; {src}: {e}: start from a random network or another "
                      f"run") from None  # fmt: skip
    if folded:
        print(f"the start's normalised inputs {folded} folded into its first layers: the "
              f"network reads them in m/s", flush=True)  # fmt: skip


def _train(cfg: PPOConfig, run: OutDir, venv, vecnorm, checkpoint, extend: bool) -> int:
    """The phases of :func:`main` (imitation, PPO, final snapshot) on a prepared env.

    ``checkpoint``: the :class:`~training.plumbing.safe_files.Snapshot` a resume continues
    from (None: a new run); ``extend``: the resume gave a new total (a run that stopped by
    its criterion trains on only then).
    """
    fs = Path(run.where())  # the run through its held descriptor: every snapshot written there
    best = -np.inf
    if available(run.path, "best"):
        best = load_state(open_snapshot(run.path, "best")).get("score", -np.inf)
    demos = None
    resuming = checkpoint is not None
    start, streak, stopped, switched_at, restarts, checked = 0, 0, False, None, [], None
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
        switched_at = state.get("starts_switched_at")
        if switched_at is not None and (type(switched_at) is not int or switched_at < 0):
            raise UntrustedFileError(f"{checkpoint.name(STATE_FILE)}: starts_switched_at must "
                                     f"be an env step count or null")  # fmt: skip
        where = checkpoint.name(STATE_FILE)
        restarts = check_restarts(state.get("restarts", []), where, start,
                                  cfg.restart.get("max", 0))  # fmt: skip
        checked = check_restart_checked(state.get("restart_checked"), where, start)
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
    elif cfg.init_from:
        model = _start_from(cfg, run, vecnorm, fs)
    else:
        model = make_model(cfg, vecnorm, fs)
    if cfg.stand_branch_frozen or cfg.walker_frozen:  # new or resumed: never learns
        from training.ppo.stand_branch import freeze_actor

        for which, frozen in (("walker", cfg.walker_frozen), ("branch", cfg.stand_branch_frozen)):
            if frozen:
                freeze_actor(model.policy, which)
    if model.num_timesteps == 0:
        try:
            initial_actions(model, cfg)
        except ValueError as e:
            raise Refusal(f"train_ppo: error: {e}") from None
        _start_brake(cfg, model.policy)
        if cfg.teacher and not available(run.path, "imitation"):  # the imitation result alone
            arrays = {"demos.npz": {"obs": demos.obs, "act": demos.act}}
            save_snapshot(fs / "imitation", model.policy, {"num_timesteps": 0}, vecnorm,
                          arrays=arrays)  # fmt: skip
    anchor = None
    if cfg.teacher and cfg.bc_anchor_steps > 0:
        from training.ppo.imitation import Anchor, Dataset

        snap = open_snapshot(run.path, "imitation")
        if "demos.npz" not in snap:
            raise UntrustedFileError(f"{snap.name('demos.npz')}: missing")
        z = read_npz(snap.name("demos.npz"), data_spec(cfg), data=snap.files["demos.npz"],
                     max_bytes=data_budget(cfg))  # fmt: skip
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
    curriculum = start_curriculum(cfg, switched_at) if cfg.start_curriculum else None
    redraw = restart_rule(cfg, restarts, checked) if cfg.restart else None

    def more_state():
        """What the checkpoint saves of the start curriculum and the restart rule."""
        return {**({"starts_switched_at": curriculum.switched_at} if curriculum else {}),
                **({"restarts": list(redraw.restarts), "restart_checked": redraw.checked}
                   if redraw else {})}  # fmt: skip

    balance = None
    if cfg.stand_balance:
        from training.ppo.exploration import stand_balance_callback

        balance = stand_balance_callback()
    if cfg.learn_rows != "all":
        from training.ppo.stand_branch import learn_rows_callback

        balance = learn_rows_callback(cfg.learn_rows)
    branch_discount = None
    if cfg.stand_gamma > 0:
        from training.ppo.stand_branch import truncation_discount

        branch_discount = truncation_discount(cfg.stand_gamma, cfg.stand_gamma_rows)
    schedules = []  # what changes with the env step: the discounts, the training env
    if cfg.gamma_final > 0 or any({"gamma", "stand_gamma", "learning_rate"} & set(e)
                                  for e in cfg.schedule):  # fmt: skip
        schedules.append(gamma_schedule(cfg, vecnorm))
    if any({"copy", "frozen"} & set(e) for e in cfg.schedule):
        schedules.append(actor_schedule(cfg, cfg.phase_at(model.num_timesteps)))
    if any("train_env" in e for e in cfg.schedule):
        phase = cfg.phase_at(model.num_timesteps)
        schedules.append(env_schedule(cfg, vecnorm, TRAIN_SEED_OFFSET + cfg.seed, phase))
    callback = make_callbacks(cfg, run, vecnorm, best, float(wall0), 0 if extend else streak,
                              more_state)  # fmt: skip
    callback.stopped = stopped
    if remaining > 0:
        print(f"PPO: {remaining} env steps to go", flush=True)
        try:
            model.learn(
                total_timesteps=remaining,
                callback=[
                    callback,
                    critic_warmup(cfg, anchor),
                    update_threads(cfg.torch_threads, cfg.update_threads or cfg.torch_threads),
                    *schedules,
                    *([branch_discount] if branch_discount else []),
                    *([curriculum] if curriculum else []),
                    *([redraw] if redraw else []),
                    *([balance] if balance else []),
                    *([progress_bar(cfg)] if cfg.progress else []),
                ],
                reset_num_timesteps=start == 0,
            )
        finally:  # TensorBoard's writer thread writes through the run's descriptor: close it
            if getattr(model, "_logger", None) is not None:  # while the descriptor is open
                model.logger.close()
        callback.checkpoint()
    wall = time.time() - t0
    save_snapshot(fs / "final", model.policy, {"num_timesteps": model.num_timesteps}, vecnorm)
    ended = (f"stopped: {stop_reason(cfg)}" if callback.stopped
             else f"the budget of {cfg.total_timesteps} env steps ended")  # fmt: skip
    publish(cfg, run, ended)
    redrawn = f"; restarts at {redraw.restarts} env steps" if redraw and redraw.restarts else ""
    run.append(
        "training_time.txt",
        f"PPO: {model.num_timesteps} env steps, {wall:.0f} s wall this session; {ended}{redrawn}\n",
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


if __name__ == "__main__":
    raise SystemExit(main())
