"""A later stage that observes more: the start's network widened with zero input columns.

A stage whose env adds observation blocks to its start's (``observation=["phase",
"gravity"]`` after a policy trained on ``["phase"]``: legged-robot RL's projected gravity) starts
from the start's weights with a zero column in both first layers (actor and critic) for every
added entry, and with those entries' statistics in the normaliser taken from reset observations
of the run's own training env (a separate instance, seeds of no protocol): read at about unit
scale from the start, as every other input. The widened network computes
exactly what the start computed, whatever the added entries hold; PPO then learns their weights
like any other. Nothing else changes shape, so the checks of any snapshot then apply
(:func:`training.ppo.policy_io.check_weights` and what follows).
"""

from __future__ import annotations

import numpy as np

from biped_constraint_env.observation import OBS_LOW, OBSERVATION_BLOCKS
from training.plumbing.safe_files import Snapshot, load_safetensors

FIRST_LAYERS = ("mlp_extractor.policy_net.0.weight", "mlp_extractor.value_net.0.weight")
"""The weights that read the observation (after the normaliser): (hidden, observation)."""
BRANCH_FIRST_LAYERS = ("branch_net.0.weight", "branch_value_net.0.weight")
"""A standing branch's (``training.ppo.stand_branch``) weights that read the observation."""
BRAKE_FIRST_LAYER = "brake_net.0.weight"
"""A braking actor's (``brake_branch``) weights that read the observation (as the walker's)."""
BRANCH_INPUT = ("branch_input.scale", "branch_input.shift")
"""A standing branch's fixed input map ``scale * x + shift`` (one entry per observation entry):
an added entry gets 1 and 0, read as the run's normaliser gives it, like the walker's."""


def added_entries(old: tuple[str, ...], new: tuple[str, ...]) -> list[int]:
    """The indices of the entries that the blocks ``new`` add to the blocks ``old``.

    ``new`` must hold every block of ``old`` in the same order, with blocks inserted anywhere
    (ValueError otherwise: a stage that drops or reorders what its start read is not a widening).
    """
    at, out, kept = len(OBS_LOW), [], 0
    for b in new:
        size = len(OBSERVATION_BLOCKS[b].names)
        if kept < len(old) and old[kept] == b:
            kept += 1
        else:
            out.extend(range(at, at + size))
        at += size
    if kept != len(old):
        raise ValueError(f"the observation's blocks {list(new)} do not hold the start's "
                         f"{list(old)} in order")  # fmt: skip
    return out


def _insert(a: np.ndarray, added: list[int], values, axis: int) -> np.ndarray:
    """``a`` with ``values`` at the (sorted) indices ``added`` of the result along ``axis``."""
    return np.insert(a, [k - i for i, k in enumerate(added)], values, axis=axis)


def widen_snapshot(snap: Snapshot, added: list[int], mean: np.ndarray, var: np.ndarray,
                   width: int | None = None) -> Snapshot:  # fmt: skip
    """An in-memory copy of ``snap`` whose network and normaliser read the ``added`` entries.

    The policy's first layers gain zero columns at ``added`` (a standing branch's and a braking
    actor's too, the branch's input map 1 and 0 there), the observation statistics ``mean`` and
    ``var`` there; every other file is the snapshot's own. ValueError where the snapshot's
    network has no such first layers (an in-network normaliser) or only part of a standing
    branch, or where a layer to widen is not float32 or does not read ``width`` inputs (the
    start's observation size), before anything is reshaped.
    """
    import torch
    from safetensors.torch import save

    from training.ppo.policy_io import (
        NORMALIZER_FILE,
        POLICY_FILE,
        normalizer_bytes,
        read_normalizer,
    )

    tensors = load_safetensors(snap.name(POLICY_FILE), snap.files[POLICY_FILE])
    if not all(k in tensors and tensors[k].dim() == 2 for k in FIRST_LAYERS):
        raise ValueError(f"{snap.path}: no first layers {FIRST_LAYERS} to widen")
    branch = [k for k in (*BRANCH_FIRST_LAYERS, *BRANCH_INPUT) if k in tensors]
    if branch and len(branch) != len(BRANCH_FIRST_LAYERS) + len(BRANCH_INPUT):
        raise ValueError(f"{snap.path}: a standing branch without all of "
                         f"{BRANCH_FIRST_LAYERS + BRANCH_INPUT} to widen")  # fmt: skip
    brake = (BRAKE_FIRST_LAYER,) if BRAKE_FIRST_LAYER in tensors else ()
    layers = FIRST_LAYERS + (BRANCH_FIRST_LAYERS if branch else ()) + brake
    vectors = BRANCH_INPUT if branch else ()
    for k in layers + vectors:
        t = tensors[k]
        if t.dtype != torch.float32:
            raise ValueError(f"{snap.path}: {k} is {str(t.dtype).removeprefix('torch.')}, "
                             f"not float32")  # fmt: skip
        got = t.shape[1] if k in layers else t.shape[0]
        if t.dim() != (2 if k in layers else 1) or (width is not None and got != width):
            raise ValueError(f"{snap.path}: {k} reads {got} inputs where the start's "
                             f"observation has {width}")  # fmt: skip
    for k in layers:
        tensors[k] = torch.from_numpy(_insert(tensors[k].numpy(), added, 0.0, axis=1))
    for k, value in zip(BRANCH_INPUT, (1.0, 0.0), strict=True) if branch else ():
        tensors[k] = torch.from_numpy(_insert(tensors[k].numpy(), added, value, axis=0))
    files = dict(snap.files)
    files[POLICY_FILE] = save({k: v.contiguous() for k, v in tensors.items()})
    if NORMALIZER_FILE in snap:
        d = read_normalizer(snap.name(NORMALIZER_FILE), data=snap.files[NORMALIZER_FILE])
        if d["norm_obs"]:
            d["obs_mean"] = _insert(d["obs_mean"], added, mean, axis=0)
            d["obs_var"] = _insert(d["obs_var"], added, var, axis=0)
        files[NORMALIZER_FILE] = normalizer_bytes(d)
    return Snapshot(snap.path, files)
