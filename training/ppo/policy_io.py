"""Policy files and checkpoints that load without unpickling anything.

A *snapshot* is a directory:

| file | what | format |
|---|---|---|
| ``policy.safetensors`` | the actor-critic's weights (in-network normaliser too) | safetensors |
| ``normalizer.npz`` | VecNormalize's statistics and settings | npz, ``allow_pickle=False`` |
| ``optimizer.safetensors`` | Adam's state (checkpoints only, for resuming) | safetensors |
| ``state.json`` | env steps, best score, phase, ... | JSON |
| ``manifest.json`` | every file's size and SHA-256 (written last: it marks completion) | JSON |

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
import hashlib
import io
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from training.plumbing.common import CliParser, command
from training.plumbing.outputs import OutDir
from training.plumbing.safe_files import (
    MANIFEST_FILE,
    MAX_WEIGHTS_BYTES,
    Snapshot,
    UntrustedFileError,
    inside,
    load_safetensors,
    read_bytes,
    read_json_object,
    read_npz,
    read_snapshot,
    read_toml,
    safetensors_header,
    verify_manifest,
)

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
MAX_TIMESTEPS = 10**12
"""Largest env-step counter a snapshot may hold (a year at 30k env steps/s is 10^12)."""


@contextlib.contextmanager
def atomic_dir(where: Path) -> Iterator[Path]:
    """Write a snapshot directory atomically: yields a fresh directory (a path into it) to fill.

    ``where``'s parent is opened once (``O_NOFOLLOW``) and everything happens through that
    descriptor: the temporary ``NAME.tmp`` is made anew (``mkdir``: nothing planted in it),
    the yielded path resolves through its own descriptor, the files are flushed and
    hashed into the manifest, the current ``where`` becomes ``NAME.prev`` and the temporary
    directory ``where`` (renames that replace links, never follow them). An exception leaves
    ``where`` and ``where.prev`` as they were.
    """
    where = Path(where)
    name = where.name
    tmp, prev = name + TMP_SUFFIX, name + PREVIOUS_SUFFIX
    with OutDir.open(where.parent) as parent:
        parent.remove(tmp)
        os.mkdir(tmp, 0o755, dir_fd=parent.fd)
        with parent.subdir(tmp, create=False) as d:
            yield Path(d.where())
            _write_manifest(d)
            d.fsync()
        if parent.kind(name) is not None:
            parent.remove(prev)
            parent.replace(name, prev)
        parent.replace(tmp, name)
        parent.fsync()


def _write_manifest(d: OutDir) -> None:
    """Record every file of ``d`` (size, SHA-256), each read back through ``d``, written last."""
    entries = {}
    for name in d.names():
        if name == MANIFEST_FILE:
            continue
        if d.kind(name) != "file":
            raise UntrustedFileError(f"{d.path / name}: a snapshot holds files only")
        data = read_bytes(Path(d.where(name)), MAX_WEIGHTS_BYTES)
        entries[name] = {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    d.write(MANIFEST_FILE, json.dumps(entries, indent=1, sort_keys=True) + "\n")


def write_manifest(where: Path) -> None:
    """Record every file of the directory ``where`` in its manifest (tests build snapshots)."""
    with OutDir.open(where, create=False) as d:
        _write_manifest(d)


def is_complete(where: Path) -> bool:
    """Whether ``where`` is a complete, intact snapshot (every file as its manifest records)."""
    return verify_manifest(where) is None


def find_snapshot(run: Path, which: str) -> Path:
    """The directory of snapshot ``which`` (:data:`SNAPSHOTS`) of a run, complete.

    Falls back to the kept previous snapshot (``NAME.prev``) when a kill interrupted the
    replacement of the newest. Raises FileNotFoundError naming what the run does have.
    """
    if which not in SNAPSHOTS:
        raise ValueError(f"which must be one of {sorted(SNAPSHOTS)}, got {which!r}")
    where = Path(run) / SNAPSHOTS[which]
    prev = where.with_name(where.name + PREVIOUS_SUFFIX)
    inside(Path(run), where.parent)  # no link on the way (checkpoints/ a link outside)
    problem = verify_manifest(where)
    if problem is None:
        return where
    if verify_manifest(prev) is None:
        if problem != "missing":
            print(f"{where} is damaged ({problem}); using {prev.name}", file=sys.stderr)
        return prev
    have = [k for k in SNAPSHOTS if available(run, k)]
    legacy = " It holds an SB3 model.zip: see import_sb3_zip." if _has_sb3_zip(run) else ""
    why = "" if problem == "missing" else f" ({problem})"
    raise FileNotFoundError(
        f"{run} has no complete {which!r} snapshot{why}; it has: {have or 'none'}.{legacy}"
    )


PUBLISHED_FILE = "published.json"
"""A run's record of the snapshot its figures are of, and why (``{"snapshot", "why"}``)."""


def published_snapshot(run: Path) -> tuple[str, str]:
    """(snapshot name, why) of the snapshot a run publishes: the one ``evaluate`` loads.

    From the run's :data:`PUBLISHED_FILE` when it has one (the name checked against
    :data:`SNAPSHOTS`); else the run's own selection rule: ``best`` (the highest score of its
    periodic evaluations on the selection seeds) when it has one, else ``final``.
    """
    path = Path(run) / PUBLISHED_FILE
    if os.path.lexists(path):
        d = read_json_object(path, Path(run))
        which, why = d.get("snapshot"), d.get("why", "")
        if (not isinstance(which, str) or which not in SNAPSHOTS or not isinstance(why, str)
                or len(why) > 500):  # fmt: skip
            raise UntrustedFileError(f"{path}: snapshot must be one of {sorted(SNAPSHOTS)} "
                                     f"with a short why")  # fmt: skip
        return which, why
    if available(run, "best"):
        return "best", "the run's selection: the best periodic evaluation on the selection seeds"
    return "final", "the run has no selection (best/) snapshot: its last weights"


def open_snapshot(run: Path, which: str) -> Snapshot:
    """Snapshot ``which`` of a run, its files read once and checked (:func:`read_snapshot`).

    The newest snapshot, else the kept previous one; with neither intact,
    :func:`find_snapshot` names what the run has. Each file is read and hashed once.
    """
    if which not in SNAPSHOTS:
        raise ValueError(f"which must be one of {sorted(SNAPSHOTS)}, got {which!r}")
    where = Path(run) / SNAPSHOTS[which]
    inside(Path(run), where.parent)  # no link on the way (checkpoints/ a link outside)
    problem = None
    for path in (where, where.with_name(where.name + PREVIOUS_SUFFIX)):
        try:
            snap = read_snapshot(path)
        except FileNotFoundError:
            continue
        except UntrustedFileError as e:
            problem = problem or str(e)
            continue
        if path != where and problem:
            print(f"{where} is damaged ({problem}); using {path.name}", file=sys.stderr)
        return snap
    return read_snapshot(find_snapshot(run, which))  # refuses, naming what the run has


def _snap(where: Path | Snapshot) -> Snapshot:
    return where if isinstance(where, Snapshot) else read_snapshot(where)


def available(run: Path, which: str) -> bool:
    """Whether a run has a complete snapshot ``which`` (or its kept previous one)."""
    where = Path(run) / SNAPSHOTS[which]
    inside(Path(run), where.parent)  # no link on the way (checkpoints/ a link outside)
    return is_complete(where) or is_complete(where.with_name(where.name + PREVIOUS_SUFFIX))


def _has_sb3_zip(run: Path) -> bool:
    return any(p.name == "model.zip" for p in Path(run).glob("*/model.zip"))


def save_snapshot(
    where: Path,
    policy,
    state: dict[str, Any],
    vecnorm=None,
    optimizer: bool = False,
    arrays: dict[str, dict[str, np.ndarray]] | None = None,
) -> None:
    """Write a snapshot of an SB3 ``policy`` (and its VecNormalize) atomically into ``where``.

    ``state``: plain data (numbers, strings, lists, dicts) saved as standard JSON (a number
    that is not finite is written as null). ``optimizer``: also save the policy optimizer's
    state (checkpoints that a resume continues from). ``arrays``: further npz files of the
    snapshot, by file name (e.g. training data).
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
        (tmp / STATE_FILE).write_text(json_text(state))


def json_text(data: Any, indent: int | None = 1) -> str:
    """Standard JSON text (NaN and infinities become null), ending in a newline."""
    return json.dumps(finite_or_null(data), indent=indent, allow_nan=False, default=float) + "\n"


def finite_or_null(x: Any) -> Any:
    """``x`` with every float that is not finite replaced by None (JSON null)."""
    if isinstance(x, float | np.floating):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, dict):
        return {k: finite_or_null(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [finite_or_null(v) for v in x]
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.ndarray):
        return finite_or_null(x.tolist())
    return x


def _counter(path: Path, state: dict, key: str, hi: int = MAX_TIMESTEPS) -> int:
    n = state.get(key, 0)
    if type(n) is not int or not 0 <= n <= hi:
        raise UntrustedFileError(f"{path}: {key} must be an integer in [0, {hi}], got {n!r}")
    return n


def _score(path: Path, state: dict, key: str) -> float:
    """A score field: a finite number, or null / absent (no score yet: -inf)."""
    v = state.get(key)
    if v is None:
        return -np.inf
    if isinstance(v, bool) or not isinstance(v, int | float) or not -1e12 <= v <= 1e12:
        raise UntrustedFileError(f"{path}: {key} must be a number in [-1e12, 1e12] or null, got "
                                 f"{str(v)[:40]}")  # fmt: skip
    return float(v)


def load_state(where: Path | Snapshot) -> dict[str, Any]:
    """The snapshot's ``state.json``, its counters checked.

    ``num_timesteps``: an integer in [0, :data:`MAX_TIMESTEPS`]; ``best`` and ``score``:
    finite numbers (null or absent: none yet, read as -inf); ``wall_s``: finite, >= 0.
    """
    if isinstance(where, Snapshot):
        path, state = where.name(STATE_FILE), where.json(STATE_FILE)
    else:
        path = Path(where) / STATE_FILE
        state = read_json_object(path)
    state["num_timesteps"] = _counter(path, state, "num_timesteps")
    for key in ("best", "score"):
        if key in state:
            state[key] = _score(path, state, key)
    wall = state.get("wall_s", 0.0)
    if isinstance(wall, bool) or not isinstance(wall, int | float) or not 0 <= wall < 1e9:
        raise UntrustedFileError(f"{path}: wall_s must be a number of seconds >= 0, got {wall!r}")
    return state


def load_weights(policy, where: Path | Snapshot) -> None:
    """Load the snapshot's weights into ``policy``: the same names and shapes, all finite."""
    import torch

    snap = _snap(where)
    path = snap.name(POLICY_FILE)
    if POLICY_FILE not in snap:
        raise UntrustedFileError(f"{path}: missing")
    shapes, _ = safetensors_header(path, data=snap.files[POLICY_FILE])
    model_sd = policy.state_dict()
    want = {k: tuple(v.shape) for k, v in model_sd.items()}
    wrong = sorted(set(shapes) - set(want)) + [
        f"{k}: {shapes[k]}, the config's {want[k]}" for k in shapes if k in want
        and shapes[k] != want[k]
    ]  # fmt: skip
    if wrong:
        raise UntrustedFileError(f"{path}: does not match the config's network ({wrong[:3]})")
    tensors = load_safetensors(path, snap.files[POLICY_FILE])
    # names the file lacks must be aliases of tensors it has (shared modules)
    loaded_ptrs = {model_sd[k].data_ptr() for k in tensors}
    missing = [k for k in want if k not in tensors and model_sd[k].data_ptr() not in loaded_ptrs]
    if missing:
        raise UntrustedFileError(
            f"{path}: does not match the config's network (lacks {missing[:3]})"
        )
    try:
        policy.load_state_dict(tensors, strict=False)
    except RuntimeError as e:
        raise UntrustedFileError(f"{path}: does not match the config's network ({e})") from None
    bad = [k for k, v in policy.state_dict().items() if v.is_floating_point()
           and not torch.isfinite(v).all()]  # fmt: skip
    if bad:
        raise UntrustedFileError(f"{path}: {bad[0]} holds NaN or inf")


def check_weights(cfg, where: Path | Snapshot) -> None:
    """Check the snapshot's weights against the config before any network is built.

    From the safetensors header alone: the hidden layers equal ``cfg.net_arch``, the input
    is the env's observation and the output its five actions. A config that asks for a
    larger network than its weights hold is refused here, not allocated.
    """
    snap = _snap(where)
    path = snap.name(POLICY_FILE)
    if POLICY_FILE not in snap:
        raise UntrustedFileError(f"{path}: missing")
    shapes, _ = safetensors_header(path, data=snap.files[POLICY_FILE])
    prefix = "features_extractor." if cfg.teacher else ""
    for net in ("policy_net", "value_net"):
        layers = []
        i = 0
        while f"mlp_extractor.{net}.{i}.weight" in shapes:
            layers.append(shapes[f"mlp_extractor.{net}.{i}.weight"])
            i += 2  # Linear, activation, Linear, ...
        arch = tuple(w[0] for w in layers)
        ins = tuple(w[1] for w in layers[:1])
        if arch != tuple(cfg.net_arch) or ins != (cfg.obs_dim(),):
            raise UntrustedFileError(
                f"{path}: {net} has layers {arch} on {ins or '?'} inputs; the config says "
                f"net_arch {list(cfg.net_arch)} on {cfg.obs_dim()} observations"
            )
    if shapes.get("action_net.weight", (0,))[0] != 5:
        raise UntrustedFileError(f"{path}: no action_net of the env's 5 actions")
    if prefix and f"{prefix}mean" not in shapes:
        raise UntrustedFileError(f"{path}: no in-network normaliser ({prefix}mean)")


def load_optimizer(policy, where: Path | Snapshot) -> None:
    """Load the snapshot's optimizer state into ``policy.optimizer``, checked against it.

    The saved hyperparameters must equal the optimizer's own (they come from the run's
    config), except the learning rate (a schedule's: finite, in (0, 1]); every moment
    tensor has its parameter's shape, finite values and a non-negative second moment; the
    step count is finite, in [0, :data:`MAX_TIMESTEPS`].
    """
    import torch

    snap = _snap(where)
    path = snap.name(OPTIMIZER_FILE)
    if OPTIMIZER_FILE not in snap:
        raise UntrustedFileError(f"{path}: missing")
    _, meta = safetensors_header(path, data=snap.files[OPTIMIZER_FILE])
    tensors = load_safetensors(path, snap.files[OPTIMIZER_FILE])
    try:
        groups = json.loads(meta["param_groups"])
        scalars = json.loads(meta["scalars"])
        if not isinstance(groups, list) or not isinstance(scalars, dict):
            raise TypeError
    except (KeyError, ValueError, TypeError, RecursionError):
        raise UntrustedFileError(f"{path}: no optimizer metadata of this package's kind") from None
    opt = policy.optimizer
    own = opt.state_dict()["param_groups"]
    params = [p for g in opt.param_groups for p in g["params"]]
    if len(groups) != len(own):
        raise UntrustedFileError(f"{path}: {len(groups)} parameter groups, the optimizer has "
                                 f"{len(own)}")  # fmt: skip
    for g, o in zip(groups, own, strict=True):
        if not isinstance(g, dict) or set(g) != set(o):
            raise UntrustedFileError(f"{path}: parameter group keys differ from the optimizer's")
        for k, v in g.items():
            if k == "lr":
                if isinstance(v, bool) or not isinstance(v, int | float) or not 0 <= v <= 1:
                    raise UntrustedFileError(f"{path}: lr must be in [0, 1], got {v!r}")
            elif json.dumps(v) != json.dumps(o[k]):
                raise UntrustedFileError(f"{path}: {k} = {v!r}, the run's optimizer has {o[k]!r}")
    if scalars:
        raise UntrustedFileError(f"{path}: unexpected scalar state {sorted(scalars)[:3]}")
    want = {}
    for pid, p in enumerate(params):
        want[f"state.{pid}.exp_avg"] = tuple(p.shape)
        want[f"state.{pid}.exp_avg_sq"] = tuple(p.shape)
        want[f"state.{pid}.step"] = ()
    if set(tensors) - set(want):
        raise UntrustedFileError(f"{path}: its tensors are not this optimizer's state")
    pids = {k.split(".")[1] for k in tensors}
    if any(
        f"state.{pid}.{k}" not in tensors for pid in pids for k in ("exp_avg", "exp_avg_sq", "step")
    ):
        raise UntrustedFileError(f"{path}: its tensors are not this optimizer's state")
    for k, t in tensors.items():
        if tuple(t.shape) != want[k] or not torch.isfinite(t).all():
            raise UntrustedFileError(f"{path}: {k} has the wrong shape or is not finite")
        if k.endswith("exp_avg_sq") and (t < 0).any():
            raise UntrustedFileError(f"{path}: {k} holds a negative second moment")
        if k.endswith("step") and not 0 <= float(t) <= MAX_TIMESTEPS:
            raise UntrustedFileError(f"{path}: {k} = {float(t)} is out of range")
    opt.load_state_dict(_unflatten_optimizer(tensors, {"param_groups": json.dumps(groups),
                                                       "scalars": "{}"}))  # fmt: skip


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
    d = {
        "obs_mean": obs_rms.mean if obs_rms is not None else empty,
        "obs_var": obs_rms.var if obs_rms is not None else empty,
        "obs_count": obs_rms.count if obs_rms is not None else 0.0,
        "ret_mean": vecnorm.ret_rms.mean,
        "ret_var": vecnorm.ret_rms.var,
        "ret_count": vecnorm.ret_rms.count,
        **{k: getattr(vecnorm, k) for k in _NORM_SETTINGS},
    }
    Path(path).write_bytes(normalizer_bytes(d))


def normalizer_bytes(d: dict[str, Any]) -> bytes:
    """The normaliser file's bytes for the statistics and settings ``d``.

    ``d`` has :func:`read_normalizer`'s keys; written as plain float64 arrays, the one format
    that both :func:`save_normalizer` and a widened snapshot write.
    """
    keys = (*_NORM_ARRAYS, *_NORM_SETTINGS)
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(d[k], dtype=np.float64) for k in keys})
    return buf.getvalue()


def read_normalizer(
    path: Path, obs_dim: int | None = None, data: bytes | None = None
) -> dict[str, Any]:
    """The npz written by :func:`save_normalizer`, each array's header checked first.

    ``obs_dim``: the observation statistics must have that length (or none, when the run
    did not normalise observations). ``data``: the file's bytes, already read. Every
    statistic is range-checked: variances and counts >= 0, epsilon and the clips > 0,
    gamma in (0, 1]. Never unpickles.
    """
    d = None if obs_dim is None else obs_dim
    spec = {k: ((None,), "f") for k in ("obs_mean", "obs_var")}
    spec.update({k: ((), "f") for k in ("obs_count", "ret_mean", "ret_var", "ret_count")})
    spec.update({k: ((), "f") for k in _NORM_SETTINGS})
    z = read_npz(path, spec, max_bytes=1 << 20, data=data)
    out = {k: z[k] for k in _NORM_ARRAYS}
    out.update({k: float(z[k]) for k in _NORM_SETTINGS})
    out["norm_obs"], out["norm_reward"] = bool(out["norm_obs"]), bool(out["norm_reward"])
    n = len(out["obs_mean"])
    if out["norm_obs"] and (n != len(out["obs_var"]) or (d is not None and n != d)):
        raise UntrustedFileError(
            f"{path}: observation statistics of length {n}/{len(out['obs_var'])}, the config's "
            f"observation has {d}"
        )
    negative = [k for k in ("obs_var", "obs_count", "ret_var", "ret_count")
                if np.any(out[k] < 0)]  # fmt: skip
    if negative:
        raise UntrustedFileError(f"{path}: {negative[0]} is negative")
    if not (out["epsilon"] > 0 and out["clip_obs"] > 0 and out["clip_reward"] > 0):
        raise UntrustedFileError(f"{path}: epsilon, clip_obs and clip_reward must be > 0")
    if not 0 < out["gamma"] <= 1:
        raise UntrustedFileError(f"{path}: gamma must be in (0, 1]")
    return out


def restore_normalizer(vecnorm, where: Path | Snapshot) -> None:
    """Set a new VecNormalize's statistics from a snapshot (to continue training)."""
    n = vecnorm.observation_space.shape[0]
    snap = _snap(where)
    if NORMALIZER_FILE not in snap:
        raise UntrustedFileError(f"{snap.name(NORMALIZER_FILE)}: missing")
    d = read_normalizer(snap.name(NORMALIZER_FILE), n, snap.files[NORMALIZER_FILE])
    if d["norm_obs"] != vecnorm.norm_obs:
        raise UntrustedFileError(f"{snap.path}: norm_obs {d['norm_obs']} differs from the run's")
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

    With ``cfg.stand_branch``, :class:`training.ppo.stand_branch.StandBranchPolicy`; with
    ``cfg.policy = "experts"``, :class:`training.ppo.experts.ExpertsPolicy`.

    ``cfg``: a :class:`training.ppo.config.PPOConfig`. The action space is [-1, 1]^5 (the
    policy's actions, mapped to torques by ``cfg.action_map()``).
    """
    from gymnasium import spaces
    from stable_baselines3.common.policies import ActorCriticPolicy

    from biped_constraint_env.observation import observation_space as env_obs_space

    if observation_space is None:
        s = cfg.settings()
        observation_space = env_obs_space(s.observation.blocks)
    act_space = spaces.Box(-1.0, 1.0, (5,), np.float32)
    cls = ActorCriticPolicy
    if cfg.stand_branch:
        from training.ppo.stand_branch import StandBranchPolicy as cls
    elif cfg.policy == "experts":
        from training.ppo.experts import ExpertsPolicy as cls
    return cls(
        observation_space, act_space, lambda _: 0.0, use_sde=cfg.use_sde, **cfg.policy_kwargs()
    )


def read_config(run: Path):
    """The :class:`training.ppo.config.PPOConfig` of a run directory (its config.toml).

    The file is data from anywhere: read bounded, every key known, every value checked
    (:meth:`PPOConfig.check_untrusted`: the registered env id, the package's own controller
    and reference names, no path).
    """
    from training.plumbing.common import check_toml_kinds, config_from_mapping
    from training.ppo.config import PPOConfig

    run = Path(run)
    path = run / "config.toml"
    if not run.is_dir():
        raise FileNotFoundError(f"{run}: no such directory")
    if not path.exists() and not path.is_symlink():
        raise FileNotFoundError(f"{run} is not a run directory (no config.toml)")
    data = read_toml(path, run)
    data.pop("out_dir", None)  # where it was written: never used from a loaded config
    try:
        check_toml_kinds(PPOConfig, data, str(path))
        cfg = config_from_mapping(PPOConfig, data, str(path))
        cfg.check_untrusted()
    except ValueError as e:
        raise UntrustedFileError(f"{path}: {e}") from None
    return cfg


def load_policy(run: Path, which: str | None = None):
    """(policy, obs normaliser, config, snapshot state) of a run's snapshot.

    ``which``: a name of :data:`SNAPSHOTS`; None: the one the run publishes
    (:func:`published_snapshot`). Reads only files inside ``run``; checks before it builds
    (:func:`check_weights`); needs the normaliser when the run normalised observations.
    Nothing is unpickled or imported.
    """
    policy, stats, cfg, state, _ = open_policy(run, which)
    return policy, ObsNormalizer(stats), cfg, state


def open_policy(run: Path, which: str | None = None):
    """:func:`load_policy`'s work: (policy, normaliser dict or None, config, state, snapshot).

    The normaliser as :func:`read_normalizer` reads it (None: the network normalises its own
    input, a teacher run); the :class:`~training.plumbing.safe_files.Snapshot` holds every file
    as it was read, once.
    """
    cfg = read_config(run)
    which = which or published_snapshot(run)[0]
    snap = open_snapshot(run, which)  # every file read once: no mixing with a replacement
    inside(Path(run), snap.path)
    state = load_state(snap)
    check_weights(cfg, snap)
    policy = build_policy(cfg)
    load_weights(policy, snap)
    policy.set_training_mode(False)
    norm_path = snap.name(NORMALIZER_FILE)
    raw = snap.files.get(NORMALIZER_FILE)
    if cfg.teacher:  # the network normalises its own input; VecNormalize kept returns only
        d = read_normalizer(norm_path, cfg.obs_dim(), raw) if raw is not None else None
        if d is not None and d["norm_obs"]:
            raise UntrustedFileError(f"{norm_path}: observation statistics in a run whose network "
                                     f"normalises its own input (a teacher run)")  # fmt: skip
        return policy, None, cfg, state, snap
    if raw is None:
        raise UntrustedFileError(f"{norm_path}: missing")
    d = read_normalizer(norm_path, cfg.obs_dim(), raw)
    if not d["norm_obs"]:
        raise UntrustedFileError(f"{norm_path}: holds no observation statistics")
    return policy, d, cfg, state, snap


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
    zip_path: Path,
    vecnormalize_pkl: Path | None,
    out: OutDir,
    state: dict | None = None,
    env: dict | None = None,
) -> None:
    """Convert a Stable-Baselines3 ``model.zip`` (+ ``vecnormalize.pkl``) to a run directory.

    ``out`` (an open output directory) receives ``config.toml`` (the network's architecture,
    read from the model, and ``env``: the keyword arguments of the env it was trained in,
    ``[env]``) and the snapshot ``final/``, so that ``python -m training.evaluation.evaluate OUT``
    runs
    it. The model's actions in [-1, 1] are taken as ``make_sb3_vec_env`` maps them (torques /
    150 N m; PD targets as they are). The model's observation size must be that env's. This
    loads the SB3 files, which unpickles them: it prints :data:`SB3_PICKLE_WARNING` first. Use
    it only on files you trust; the directory it writes loads without pickle.
    """
    from dataclasses import replace

    from stable_baselines3 import PPO

    from training.plumbing.common import to_toml
    from training.ppo.config import ACTIVATIONS, PPOConfig, activation_fn

    print(SB3_PICKLE_WARNING.format(path=zip_path), file=sys.stderr, flush=True)
    model = PPO.load(zip_path, device="cpu")
    pol = model.policy
    arch = pol.net_arch["pi"] if isinstance(pol.net_arch, dict) else pol.net_arch
    act = [a for a in ACTIVATIONS if activation_fn(a) is pol.activation_fn]
    n_obs = pol.observation_space.shape[0]
    cfg = replace(
        PPOConfig(), env=dict(env or {}), net_arch=tuple(arch), activation=act[0] if act else "",
        use_sde=bool(model.use_sde), total_timesteps=int(model.num_timesteps),
    )  # fmt: skip
    if not act or pol.action_space.shape != (5,):
        raise ValueError(f"{zip_path}: not a ConstrainedBiped-v0 MlpPolicy of this package's kind")
    if n_obs != cfg.obs_dim():
        raise ValueError(
            f"{zip_path}: observes {n_obs} entries, the env {cfg.env} gives "
            f"{cfg.obs_dim()}; give the env it was trained in (--env KEY=VALUE)"
        )
    vecnorm = None
    if vecnormalize_pkl is not None:
        from stable_baselines3.common.vec_env import VecNormalize

        from training.ppo.sb3_vec import make_sb3_vec_env

        print(SB3_PICKLE_WARNING.format(path=vecnormalize_pkl), file=sys.stderr, flush=True)
        vecnorm = VecNormalize.load(str(vecnormalize_pkl), make_sb3_vec_env(1, 0, cfg.env, "dummy"))
    if vecnorm is None or not vecnorm.norm_obs:
        raise ValueError(f"{zip_path}: give its --vecnormalize (observation statistics)")
    cfg.validate()
    d = Path(out.where())
    save_snapshot(
        d / "final", pol, {"num_timesteps": int(model.num_timesteps), **(state or {})}, vecnorm
    )
    out.write("config.toml", to_toml(cfg))


@command("policy_io")
def main(argv: list[str] | None = None) -> int:
    """Convert a policy: ``import-sb3`` or ``export-onnx``.

    ``python -m training.ppo.policy_io import-sb3 MODEL.zip --vecnormalize PKL --out DIR``;
    ``python -m training.ppo.policy_io export-onnx POLICY OUT.onnx``
    (:mod:`training.ppo.onnx_export`).
    """
    from training.plumbing.outputs import command_output

    ap = CliParser(description="Convert an SB3 model.zip to a pickle-free snapshot, or a "
                               "policy to ONNX")  # fmt: skip
    sub = ap.add_subparsers(dest="cmd", required=True)
    imp = sub.add_parser("import-sb3", help="model.zip + vecnormalize.pkl -> a run directory")
    imp.add_argument("model_zip", type=Path)
    imp.add_argument("--vecnormalize", type=Path, required=True, help="its VecNormalize pickle")
    imp.add_argument("--out", type=Path, required=True, help="run directory to write")
    imp.add_argument(
        "--env",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="the env it was trained in (gym.make's kwargs as TOML values)",
    )
    onx = sub.add_parser("export-onnx", help="a policy -> one ONNX graph (observation in, "
                         "action out; the onnx extra)")  # fmt: skip
    onx.add_argument("policy", type=Path, help="a policy or run directory")
    onx.add_argument("out", type=Path, help="the .onnx file to write (a new path)")
    onx.add_argument("--which", choices=sorted(SNAPSHOTS), default=None,
                     help="the snapshot (default: the one the policy publishes)")  # fmt: skip
    a = ap.parse_args(argv)
    if a.cmd == "export-onnx":
        return _export_onnx_command(ap, a)
    from training.plumbing.common import parse_assignment

    try:
        env = dict(parse_assignment(item, "--env") for item in a.env)
    except ValueError as e:
        ap.error(str(e))
    for path in (a.model_zip, a.vecnormalize):
        if not path.is_file():
            ap.error(f"{path}: no such file")
    with command_output(a.out, "import-sb3") as co:
        try:
            import_sb3_zip(a.model_zip, a.vecnormalize, co.dir(), env=env)
        except ValueError as e:
            ap.error(str(e))
    print(f"wrote {a.out}")
    return 0


def _export_onnx_command(ap, a) -> int:
    """``export-onnx POLICY OUT.onnx``: refused before any loading where OUT is taken."""
    if a.out.suffix != ".onnx":
        ap.error(f"{a.out}: give a path ending in .onnx")
    if os.path.lexists(a.out):
        ap.error(f"{a.out}: exists; give a new path (nothing is overwritten)")
    if not a.policy.is_dir():
        ap.error(f"{a.policy}: no such directory")
    try:
        from training.ppo.onnx_export import export_onnx
    except ImportError as e:
        ap.error(f"export-onnx needs the onnx extra: pip install -e '.[onnx]' ({e.name} missing)")
    try:
        which = a.which or published_snapshot(a.policy)[0]
        policy, norm, cfg, _ = load_policy(a.policy, which)
        data, err = export_onnx(policy, norm, cfg, policy_batch_actor(policy, norm, cfg),
                                str(a.policy))  # fmt: skip
    except (FileNotFoundError, UntrustedFileError, ValueError) as e:
        ap.error(str(e))
    from training.plumbing.outputs import OutDir

    with OutDir.open(a.out.parent) as d:
        d.create_new(a.out.name)  # refused if anything appeared there meanwhile
        try:
            d.write(a.out.name, data)
        except BaseException:  # a full disk, Ctrl-C: not even the empty file is left
            d.remove(a.out.name)
            raise
    print(
        f"wrote {a.out} ({len(data)} bytes): {which}/ of {a.policy}; input obs (batch, "
        f"observation) float64; "
        f"outputs action, env_action; onnxruntime within {err:.2g} of the network"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
