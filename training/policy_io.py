"""Policy files and checkpoints that load without unpickling anything.

A *snapshot* is a directory:

| file | what | format |
|---|---|---|
| ``policy.safetensors`` | the actor-critic's weights (in-network normaliser too) | safetensors |
| ``normalizer.npz`` | VecNormalize's statistics and settings | npz, ``allow_pickle=False`` |
| ``optimizer.safetensors`` | Adam's state (checkpoints only, for resuming) | safetensors |
| ``state.json`` | env steps, best score, phase, ... (written last: it marks completion) | JSON |

The network's architecture comes from the run's ``config.toml`` (plain TOML), so nothing in a
policy directory is code: a downloaded policy cannot run anything when it is loaded.
Stable-Baselines3's own ``model.zip`` (cloudpickled entries) and ``vecnormalize.pkl``
(a pickle) do run code when loaded; :func:`import_sb3_zip` converts such files, with a
warning, for files the user trusts.

Snapshots are written atomically (:func:`atomic_dir`: into a temporary directory, then
renamed), and the previous one is kept as ``NAME.prev``, so that a run killed at any instant
leaves a complete snapshot to resume from (:func:`find_snapshot`).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

POLICY_FILE = "policy.safetensors"
NORMALIZER_FILE = "normalizer.npz"
OPTIMIZER_FILE = "optimizer.safetensors"
STATE_FILE = "state.json"
PREVIOUS_SUFFIX = ".prev"
TMP_SUFFIX = ".tmp"
SNAPSHOTS = {
    "final": "final",
    "best": "best",
    "imitation": "imitation",
    "checkpoint": "checkpoints/latest",
}
"""Snapshot names (``evaluate --which``) and their directories in a run."""
SB3_PICKLE_WARNING = (
    "WARNING: {path} is a Stable-Baselines3 file; loading it unpickles objects, which can run "
    "arbitrary code. Only convert files you made yourself or fully trust."
)


# ------------------------------------------------------------------------- snapshot files
def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_dir(where: Path) -> Iterator[Path]:
    """Write a snapshot directory atomically: yields a temporary directory to fill.

    On leaving, the files are flushed, the current ``where`` (if any) becomes
    ``where.prev`` (replacing the older one) and the temporary directory becomes ``where``.
    An exception leaves ``where`` and ``where.prev`` as they were.
    """
    where = Path(where)
    tmp = where.with_name(where.name + TMP_SUFFIX)
    prev = where.with_name(where.name + PREVIOUS_SUFFIX)
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    yield tmp
    for f in tmp.iterdir():
        with open(f, "rb") as fh:
            os.fsync(fh.fileno())
    _fsync_dir(tmp)
    if where.exists():
        shutil.rmtree(prev, ignore_errors=True)
        where.rename(prev)
    tmp.rename(where)
    _fsync_dir(where.parent)


def is_complete(where: Path) -> bool:
    """Whether ``where`` is a complete snapshot (its state file, written last, is there)."""
    return (Path(where) / STATE_FILE).is_file()


def find_snapshot(run: Path, which: str) -> Path:
    """The directory of snapshot ``which`` (:data:`SNAPSHOTS`) of a run, complete.

    Falls back to the kept previous snapshot (``NAME.prev``) when a kill interrupted the
    replacement of the newest. Raises FileNotFoundError naming what the run does have.
    """
    if which not in SNAPSHOTS:
        raise ValueError(f"which must be one of {sorted(SNAPSHOTS)}, got {which!r}")
    where = Path(run) / SNAPSHOTS[which]
    for cand in (where, where.with_name(where.name + PREVIOUS_SUFFIX)):
        if is_complete(cand):
            return cand
    have = [k for k in SNAPSHOTS if available(run, k)]
    legacy = " It holds an SB3 model.zip: see import_sb3_zip." if _has_sb3_zip(run) else ""
    raise FileNotFoundError(
        f"{run} has no complete {which!r} snapshot; it has: {have or 'none'}.{legacy}"
    )


def available(run: Path, which: str) -> bool:
    """Whether a run has a complete snapshot ``which`` (or its kept previous one)."""
    where = Path(run) / SNAPSHOTS[which]
    return is_complete(where) or is_complete(where.with_name(where.name + PREVIOUS_SUFFIX))


def _has_sb3_zip(run: Path) -> bool:
    return any(Path(run).glob("**/model.zip"))


def save_snapshot(
    where: Path,
    policy,
    state: dict[str, Any],
    vecnorm=None,
    optimizer: bool = False,
    arrays: dict[str, dict[str, np.ndarray]] | None = None,
) -> None:
    """Write a snapshot of an SB3 ``policy`` (and its VecNormalize) atomically into ``where``.

    ``state``: plain data (numbers, strings, lists, dicts) saved as JSON. ``optimizer``: also
    save the policy optimizer's state (checkpoints that a resume continues from). ``arrays``:
    further npz files of the snapshot, by file name (e.g. training data).
    """
    from safetensors.torch import save_file, save_model

    with atomic_dir(where) as tmp:
        save_model(policy, str(tmp / POLICY_FILE))
        if optimizer:
            tensors, meta = _flatten_optimizer(policy.optimizer.state_dict())
            save_file(tensors, str(tmp / OPTIMIZER_FILE), metadata=meta)
        if vecnorm is not None:
            save_normalizer(vecnorm, tmp / NORMALIZER_FILE)
        for name, content in (arrays or {}).items():
            np.savez(tmp / name, **content)
        (tmp / STATE_FILE).write_text(json.dumps(state, indent=1) + "\n")


def load_state(where: Path) -> dict[str, Any]:
    """The snapshot's ``state.json``."""
    return json.loads((Path(where) / STATE_FILE).read_text())


def load_weights(policy, where: Path) -> None:
    """Load the snapshot's weights into ``policy`` (every tensor must match: strict)."""
    from safetensors.torch import load_model

    missing, unexpected = load_model(policy, str(Path(where) / POLICY_FILE), strict=True)
    if missing or unexpected:  # strict raises first; kept for clarity
        raise ValueError(f"weights do not match the policy: {missing} {unexpected}")


def load_optimizer(policy, where: Path) -> None:
    """Load the snapshot's optimizer state into ``policy.optimizer``."""
    from safetensors import safe_open

    path = Path(where) / OPTIMIZER_FILE
    with safe_open(str(path), framework="pt") as fh:
        meta = fh.metadata()
        tensors = {k: fh.get_tensor(k) for k in fh.keys()}  # noqa: SIM118 (safe_open API)
    policy.optimizer.load_state_dict(_unflatten_optimizer(tensors, meta))


def _flatten_optimizer(sd: dict) -> tuple[dict, dict[str, str]]:
    """A torch optimizer state dict as flat tensors and JSON metadata (safetensors' form)."""
    import torch

    tensors, scalars = {}, {}
    for pid, entries in sd["state"].items():
        for k, v in entries.items():
            key = f"state.{pid}.{k}"
            if isinstance(v, torch.Tensor):
                tensors[key] = v.detach().clone().contiguous()
            else:
                scalars[key] = v
    meta = {"param_groups": json.dumps(sd["param_groups"]), "scalars": json.dumps(scalars)}
    return tensors, meta


def _unflatten_optimizer(tensors: dict, meta: dict[str, str]) -> dict:
    state: dict[int, dict] = {}
    items = list(tensors.items()) + list(json.loads(meta["scalars"]).items())
    for key, v in items:
        _, pid, k = key.split(".", 2)
        state.setdefault(int(pid), {})[k] = v
    return {"state": state, "param_groups": json.loads(meta["param_groups"])}


# ------------------------------------------------------------------------- normaliser
_NORM_ARRAYS = ("obs_mean", "obs_var", "obs_count", "ret_mean", "ret_var", "ret_count")
_NORM_SETTINGS = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon")


def save_normalizer(vecnorm, path: Path) -> None:
    """VecNormalize's running statistics and settings as an npz of plain arrays.

    A VecNormalize that does not normalise observations has no observation statistics
    (SB3 creates none): empty arrays stand for them.
    """
    obs_rms = vecnorm.__dict__.get("obs_rms")  # getattr would search the wrapped env
    empty = np.zeros(0)
    np.savez(
        path,
        obs_mean=obs_rms.mean if obs_rms is not None else empty,
        obs_var=obs_rms.var if obs_rms is not None else empty,
        obs_count=np.float64(obs_rms.count if obs_rms is not None else 0.0),
        ret_mean=np.asarray(vecnorm.ret_rms.mean, np.float64),
        ret_var=np.asarray(vecnorm.ret_rms.var, np.float64),
        ret_count=np.float64(vecnorm.ret_rms.count),
        **{k: np.float64(getattr(vecnorm, k)) for k in _NORM_SETTINGS},
    )


def read_normalizer(path: Path) -> dict[str, Any]:
    """The npz written by :func:`save_normalizer` (never unpickles: ``allow_pickle=False``)."""
    with np.load(path, allow_pickle=False) as z:
        out = {k: z[k].copy() for k in _NORM_ARRAYS}
        out.update({k: z[k].item() for k in _NORM_SETTINGS})
    out["norm_obs"], out["norm_reward"] = bool(out["norm_obs"]), bool(out["norm_reward"])
    return out


def restore_normalizer(vecnorm, where: Path) -> None:
    """Set a new VecNormalize's statistics from a snapshot (to continue training)."""
    d = read_normalizer(Path(where) / NORMALIZER_FILE)
    if d["norm_obs"] != vecnorm.norm_obs:
        raise ValueError(f"{where}: norm_obs {d['norm_obs']} differs from the run's")
    if d["norm_obs"]:
        vecnorm.obs_rms.mean, vecnorm.obs_rms.var = d["obs_mean"], d["obs_var"]
        vecnorm.obs_rms.count = float(d["obs_count"])
    vecnorm.ret_rms.mean, vecnorm.ret_rms.var = d["ret_mean"], d["ret_var"]
    vecnorm.ret_rms.count = float(d["ret_count"])


class ObsNormalizer:
    """The observation half of VecNormalize, frozen: ``clip((obs - mean) / sqrt(var + eps))``.

    Computes exactly what ``VecNormalize.normalize_obs`` computes (identity when the run
    did not normalise observations).
    """

    def __init__(self, d: dict[str, Any] | None):
        """From :func:`read_normalizer`'s dict (None: identity)."""
        self.enabled = bool(d and d["norm_obs"])
        if self.enabled:
            self.mean, self.var = d["obs_mean"], d["obs_var"]
            self.eps, self.clip = d["epsilon"], d["clip_obs"]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Normalised float32 observations (n, 24) -> the network's input."""
        o = obs.astype(np.float32)
        if not self.enabled:
            return o
        return np.clip((o - self.mean) / np.sqrt(self.var + self.eps), -self.clip, self.clip)


# ------------------------------------------------------------------------- policies
def build_policy(cfg, observation_space=None):
    """A fresh SB3 ``ActorCriticPolicy`` (``MlpPolicy``) of the architecture in ``cfg``.

    ``cfg``: a :class:`training.ppo_config.PPOConfig`. The action space is [-1, 1]^5 (the
    policy's actions, mapped to torques by ``cfg.action_map()``).
    """
    from gymnasium import spaces
    from stable_baselines3.common.policies import ActorCriticPolicy

    from biped_constraint_env.observation import observation_space as env_obs_space

    if observation_space is None:
        observation_space = env_obs_space(cfg.phase_obs, cfg.reference_obs)
    act_space = spaces.Box(-1.0, 1.0, (5,), np.float32)
    return ActorCriticPolicy(
        observation_space, act_space, lambda _: 0.0, use_sde=cfg.use_sde, **cfg.policy_kwargs()
    )


def read_config(run: Path):
    """The :class:`training.ppo_config.PPOConfig` of a run directory (its config.toml)."""
    from training.common import parse_config
    from training.ppo_config import PPOConfig

    path = Path(run) / "config.toml"
    if not path.is_file():
        raise FileNotFoundError(f"{run} is not a run directory (no config.toml)")
    return parse_config(PPOConfig, ["--config", str(path)], "")


def load_policy(run: Path, which: str = "final"):
    """(policy, obs normaliser, config, snapshot state) of a run's snapshot, without pickle."""
    cfg = read_config(run)
    where = find_snapshot(run, which)
    policy = build_policy(cfg)
    load_weights(policy, where)
    policy.set_training_mode(False)
    norm_path = where / NORMALIZER_FILE
    norm = ObsNormalizer(read_normalizer(norm_path) if norm_path.is_file() else None)
    return policy, norm, cfg, load_state(where)


def policy_actor(policy, normalizer: ObsNormalizer, cfg):
    """Obs (d,) -> torques (5,) [N m] of the deterministic policy (through its ActionMap)."""
    batch = policy_batch_actor(policy, normalizer, cfg)

    def act(obs: np.ndarray) -> np.ndarray:
        return batch(obs[None, :])[0]

    return act


def policy_batch_actor(policy, normalizer: ObsNormalizer, cfg):
    """Obs (n, d) -> torques (n, 5) [N m] of the deterministic policy, one forward for all."""
    amap = cfg.action_map()

    def act(obs: np.ndarray) -> np.ndarray:
        action, _ = policy.predict(normalizer(obs), deterministic=True)
        return amap(action, obs)

    return act


# ------------------------------------------------------------------------- SB3 zips
def import_sb3_zip(
    zip_path: Path, vecnormalize_pkl: Path | None, out: Path, state: dict | None = None
) -> None:
    """Convert a Stable-Baselines3 ``model.zip`` (+ ``vecnormalize.pkl``) to a snapshot.

    This loads the SB3 files, which unpickles them: it prints :data:`SB3_PICKLE_WARNING`
    first. Use it only on files you trust; the snapshot it writes loads without pickle.
    """
    from stable_baselines3 import PPO

    print(SB3_PICKLE_WARNING.format(path=zip_path), file=sys.stderr, flush=True)
    model = PPO.load(zip_path, device="cpu")
    vecnorm = None
    if vecnormalize_pkl is not None:
        from stable_baselines3.common.vec_env import VecNormalize

        from training.sb3_vec import make_sb3_vec_env

        print(SB3_PICKLE_WARNING.format(path=vecnormalize_pkl), file=sys.stderr, flush=True)
        vecnorm = VecNormalize.load(str(vecnormalize_pkl), make_sb3_vec_env(1, 0, {}, "dummy"))
    save_snapshot(
        out, model.policy, {"num_timesteps": int(model.num_timesteps), **(state or {})}, vecnorm
    )


def main(argv: list[str] | None = None) -> int:
    """``python -m training.policy_io import-sb3 MODEL.zip [--vecnormalize PKL] --out DIR``."""
    import argparse

    ap = argparse.ArgumentParser(description="Convert an SB3 model.zip to a pickle-free snapshot")
    sub = ap.add_subparsers(dest="cmd", required=True)
    imp = sub.add_parser("import-sb3", help="model.zip (+ vecnormalize.pkl) -> snapshot dir")
    imp.add_argument("model_zip", type=Path)
    imp.add_argument("--vecnormalize", type=Path, default=None)
    imp.add_argument("--out", type=Path, required=True, help="snapshot directory to write")
    a = ap.parse_args(argv)
    import_sb3_zip(a.model_zip, a.vecnormalize, a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
