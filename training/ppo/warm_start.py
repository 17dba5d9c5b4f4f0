"""The imitation warm start of a PPO run: DART demonstrations and DAgger rounds of the teacher.

Used by :mod:`training.ppo.train` for a config with a ``teacher``; every round is
checkpointed (``checkpoints/imitation``) and a resumed run continues from the last complete
round with the same result.
"""

from __future__ import annotations

import csv
import io
import json
import time
from pathlib import Path

import numpy as np

from biped_constraint_env.actions import TORQUE_LIMIT_NM
from training.plumbing.common import (
    progress,
)
from training.plumbing.outputs import OutDir
from training.plumbing.rollouts import run_episodes
from training.plumbing.safe_files import read_npz
from training.ppo.config import (
    DEMO_SEED_OFFSET,
    IMITATION_CHECK_SEED_OFFSET,
    PPOConfig,
    bc_weights,
)
from training.ppo.policy_io import (
    UntrustedFileError,
    is_complete,
    load_state,
    load_weights,
    save_snapshot,
)

IMITATION_CKPT = "checkpoints/imitation"
"""Snapshot of the imitation phase after each DAgger round (policy, data, round, RNG)."""


def data_spec(cfg: PPOConfig) -> dict:
    """The shapes of a snapshot's labelled data (observations, actions), for :func:`read_npz`."""
    return {"obs": ((None, cfg.obs_dim()), "f"), "act": ((None, 5), "f")}


def data_budget(cfg: PPOConfig) -> int:
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

    from training.controller.model_controller import controller_from
    from training.ppo import imitation

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
        model, data, (k0, seed, rows, wall) = resume_imitation(cfg, where, make_model, rng)
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
        rows.append(imitation_round(cfg, model, data, k, gear, eta, t0))
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


def resume_imitation(cfg: PPOConfig, where: Path, make_model, rng):
    """(model, data, (round, seed, rows, wall_s)) of an imitation checkpoint; the RNG restored."""
    from training.plumbing.safe_files import read_snapshot
    from training.ppo import imitation

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
    z = read_npz(snap.name("data.npz"), data_spec(cfg), data=snap.files["data.npz"],
                 max_bytes=data_budget(cfg))  # fmt: skip
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


def imitation_round(cfg: PPOConfig, model, data, k: int, gear, eta: str, t0: float) -> dict:
    """Round ``k``'s fit of the data into the policy, and 5 student episodes: its csv row."""
    from training.ppo import imitation

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
