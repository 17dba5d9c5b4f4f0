"""A policy as one ONNX graph: the raw observation in, the action out (``export-onnx``).

    python -m training.ppo.policy_io export-onnx POLICY OUT.onnx [--which best]

The graph holds what runs at run time for a network-alone policy: the frozen observation
normaliser (float64, as :class:`~training.ppo.policy_io.ObsNormalizer` computes it), the network's
deterministic action (every actor and gate of it, as SB3's ``predict`` computes it), clipped to
[-1, 1] (``action``, float32) and mapped to what the env takes (``env_action``, float64: torques in
N m, or PD targets in [-1, 1]). A policy that acts as a residual on the model controller is
refused: the controller is Python, not a network. The export is checked before it is written:
onnxruntime's actions on 256 observations about the normaliser's statistics must equal the
network's within :data:`TOLERANCE`. Needs the ``onnx`` extra (onnx, onnxscript, onnxruntime).
"""

from __future__ import annotations

import contextlib
import io
import logging
import warnings

import numpy as np

TOLERANCE = 1e-5
"""Largest difference between onnxruntime's and the network's actions in [-1, 1] accepted."""
OPSET = 18
INPUT, OUTPUTS = "obs", ("action", "env_action")


def _module(policy, norm, gear):
    """The torch module the graph is exported from (normaliser, network, clip, map)."""
    import torch

    d = policy.observation_space.shape[0]

    class Exported(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.policy = policy
            mean = norm.mean if norm.enabled else np.zeros(d)
            std = np.sqrt(norm.var + norm.eps) if norm.enabled else np.ones(d)
            self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float64))
            self.register_buffer("std", torch.as_tensor(std, dtype=torch.float64))
            self.clip = float(norm.clip) if norm.enabled else None
            gears = np.array(np.broadcast_to(gear, (5,)), dtype=np.float64)
            self.register_buffer("gear", torch.as_tensor(gears))

        def forward(self, obs):
            x = (obs.double() - self.mean) / self.std
            if self.clip is not None:
                x = x.clamp(-self.clip, self.clip)
            a = self.policy.get_distribution(x.float()).distribution.mean.clamp(-1.0, 1.0)
            return a, a.double() * self.gear

    return Exported().eval()


def export_onnx(policy, norm, cfg, actor, where: str = "the policy") -> tuple[bytes, float]:
    """(the ONNX model's bytes, onnxruntime's largest difference) of a loaded policy.

    ``policy``, ``norm`` and ``cfg``: :func:`training.ppo.policy_io.load_policy`'s; ``actor``:
    its batch actor, observations -> the env's actions, to check against.

    ValueError where the policy cannot be exported (a residual on the model controller) or
    where onnxruntime's actions differ from the network's by more than :data:`TOLERANCE`.
    """
    import onnxruntime as ort
    import torch

    if cfg.base_controller:
        raise ValueError(f"{where}: its network is a residual on the model controller "
                         f"{cfg.base_controller!r}, which is not a network: no ONNX graph "
                         f"of it")  # fmt: skip
    amap = cfg.action_map()
    module = _module(policy, norm, amap.gear)
    d = policy.observation_space.shape[0]
    example = torch.zeros(2, d, dtype=torch.float64)
    validate = torch.distributions.Distribution._validate_args
    torch.distributions.Distribution.set_default_validate_args(False)  # no data-dependent checks
    quiet = logging.getLogger("torch.onnx")  # its notes on torchvision's absent operators
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")  # the exporter's deprecation notes, not ours
            program = torch.onnx.export(module, (example,), dynamo=True, opset_version=OPSET,
                                        input_names=[INPUT], output_names=list(OUTPUTS),
                                        dynamic_shapes={"obs": {0: torch.export.Dim("batch")}},
                                        verbose=False)  # fmt: skip
    finally:
        torch.distributions.Distribution.set_default_validate_args(validate)
        quiet.setLevel(level)
    data = program.model_proto.SerializeToString()
    rng = np.random.default_rng(0)
    scale = np.sqrt(norm.var) if norm.enabled else 1.0
    obs = rng.normal(0.0, 1.0, (256, d)) * scale + (norm.mean if norm.enabled else 0.0)
    with torch.no_grad():
        want, _ = policy.predict(norm(obs), deterministic=True)
    session = ort.InferenceSession(data, providers=["CPUExecutionProvider"])
    got, env_action = session.run(list(OUTPUTS), {INPUT: obs})
    err = float(np.abs(got - want).max())
    env_err = float(np.abs(env_action - actor(obs)).max())
    if not err <= TOLERANCE or not env_err <= TOLERANCE * float(np.max(amap.gear)):
        raise ValueError(f"{where}: onnxruntime's actions differ from the network's by "
                         f"{max(err, env_err):.3g} (tolerance {TOLERANCE})")  # fmt: skip
    return data, err
