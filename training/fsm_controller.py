"""A finite-state feedback controller: per-model PD targets, computed from the observation.

The controller reads only the env's observation (joint angles and rates, hip position and
velocity relative to the stance toe, the model one-hot) and returns the five joint torques, so
it runs through the unchanged env, batched or single. Its parameters are one vector (the
layout is :data:`PARAM_NAMES`); ``python -m training.optimize_fsm`` tunes it by a cross-entropy
search, and PPO can learn a residual on top of it (``train_ppo --base-controller``).

Per model ``m`` (1..4), in the chain's own coordinates (so the roles follow the renumbering):

* swing hip (tau3): PD on the swing thigh's angle from the downward vertical, target
  ``hip_target[m] + hip_fb_y * hip_y_rel_toe + hip_fb_v * hip_vy`` (SIMBICON-style foot
  placement: step further when ahead or fast);
* swing knee (tau4) and swing foot (tau5): PD toward targets that blend, by a logistic of the
  swing thigh's angle about ``phase_angle``, from a "behind" set (clearance) to an "ahead" set
  (landing);
* stance knee (tau2): PD toward ``stance_knee[m]``;
* stance ankle (tau1): ``ankle_ff[m]`` plus feedback on the hip's position and velocity and on
  the swing thigh's angle, plus PD holding the stance foot's pitch theta0 near ``foot_target``
  while it pivots on the toe (the reaction of tau1 turns the foot).

Gains enter as absolute values; torques are clipped to the env's limit.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from biped_constraint_env.env import OBS_NAMES, TORQUE_LIMIT_NM

_MODES = ("m1", "m2", "m3", "m4")
PARAM_NAMES: tuple[str, ...] = (
    *(f"hip_target_{m}" for m in _MODES),
    *(f"knee_behind_{m}" for m in _MODES),
    *(f"foot_behind_{m}" for m in _MODES),
    *(f"stance_knee_{m}" for m in _MODES),
    *(f"ankle_ff_{m}" for m in _MODES),
    "hip_fb_y",
    "hip_fb_v",
    "kp_hip",
    "kd_hip",
    "kp_knee",
    "kd_knee",
    "kp_foot",
    "kd_foot",
    "kp_stance_knee",
    "kd_stance_knee",
    "ankle_fb_y",
    "ankle_fb_v",
    "phase_angle",
    "ankle_fb_swing",
    *(f"knee_ahead_{m}" for m in _MODES),
    *(f"foot_ahead_{m}" for m in _MODES),
    "kp_stance_foot",
    "foot_target",
    "kd_stance_foot",
)
"""Names of the controller's parameters, in vector order (angles in rad, torques in N m,
gains in N m/rad and N m s/rad, feedback gains in rad/m, rad s/m, N m/m, N m s/m, N m/rad)."""
N_PARAMS = len(PARAM_NAMES)
PHASE_WIDTH_RAD = 0.1  # width of the logistic blend from the "behind" to the "ahead" targets

_I = {n: OBS_NAMES.index(n) for n in OBS_NAMES}


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _block(x, name, m, n):
    start = PARAM_NAMES.index(f"{name}_m1")
    return x[:, start : start + 4][np.arange(n), m]


def swing_angles(obs: np.ndarray):
    """Swing thigh angle from the downward vertical, swing foot pitch, and their rates.

    Angles in rad (thigh: + forward; foot: 0 = flat), rates in rad/s, from observations
    (n, 24), by MODEL.md's absolute link angles.
    """
    th0, w0 = obs[:, _I["theta0"]], obs[:, _I["theta0_dot"]]
    q = obs[:, _I["q1"] : _I["q5"] + 1]
    qd = obs[:, _I["q1_dot"] : _I["q5_dot"] + 1]
    phi3 = th0 + np.pi / 2 + q[:, 0] + q[:, 1] + np.pi + q[:, 2]
    phi5 = phi3 + q[:, 3] + np.pi / 2 + q[:, 4]
    w3 = w0 + qd[:, :3].sum(1)
    return _wrap(phi3 - 1.5 * np.pi), _wrap(phi5), w3, w3 + qd[:, 3] + qd[:, 4]


def torques(x: np.ndarray, obs: np.ndarray, limit: float = TORQUE_LIMIT_NM) -> np.ndarray:
    """Joint torques [N m] (n, 5) for parameter rows ``x`` (n or 1, N_PARAMS) and obs (n, 24)."""
    obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
    n = len(obs)
    x = np.broadcast_to(np.atleast_2d(np.asarray(x, dtype=np.float64)), (n, N_PARAMS))
    p = {name: x[:, i] for i, name in enumerate(PARAM_NAMES)}
    m = np.argmax(obs[:, _I["mode_1"] : _I["mode_4"] + 1], axis=1)
    q = obs[:, _I["q1"] : _I["q5"] + 1]
    qd = obs[:, _I["q1_dot"] : _I["q5_dot"] + 1]
    th0, w0 = obs[:, _I["theta0"]], obs[:, _I["theta0_dot"]]
    hy, hv = obs[:, _I["hip_y_rel_stance_toe"]], obs[:, _I["hip_vy"]]
    swing, foot, w3, w5 = swing_angles(obs)
    ahead = 1.0 / (1.0 + np.exp(-(swing - p["phase_angle"]) / PHASE_WIDTH_RAD))
    g = {k: np.abs(p[k]) for k in PARAM_NAMES if k.startswith(("kp_", "kd_"))}
    hip_t = _block(x, "hip_target", m, n) + p["hip_fb_y"] * hy + p["hip_fb_v"] * hv
    knee_t = _block(x, "knee_behind", m, n) * (1 - ahead) + _block(x, "knee_ahead", m, n) * ahead
    foot_t = _block(x, "foot_behind", m, n) * (1 - ahead) + _block(x, "foot_ahead", m, n) * ahead
    tau = np.empty((n, 5))
    tau[:, 0] = (
        _block(x, "ankle_ff", m, n)
        + p["ankle_fb_y"] * hy
        + p["ankle_fb_v"] * hv
        + p["ankle_fb_swing"] * swing
        - g["kp_stance_foot"] * (p["foot_target"] - th0)
        + g["kd_stance_foot"] * w0
    )
    tau[:, 1] = (
        g["kp_stance_knee"] * (_block(x, "stance_knee", m, n) - q[:, 1])
        - g["kd_stance_knee"] * qd[:, 1]
    )
    tau[:, 2] = g["kp_hip"] * (hip_t - swing) - g["kd_hip"] * w3
    tau[:, 3] = g["kp_knee"] * (knee_t - q[:, 3]) - g["kd_knee"] * qd[:, 3]
    tau[:, 4] = g["kp_foot"] * (foot_t - foot) - g["kd_foot"] * w5
    return np.clip(tau, -limit, limit)


def save(x: np.ndarray, path: Path, comment: str = "", measured: dict | None = None) -> None:
    """Write parameters as JSON ({name: value}), with a comment and the measured step counts."""
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (N_PARAMS,) or not np.all(np.isfinite(x)):
        raise ValueError(f"parameters must be {N_PARAMS} finite numbers, got shape {x.shape}")
    d = {
        "comment": comment,
        "measured": measured or {},
        "params": dict(zip(PARAM_NAMES, x.tolist(), strict=True)),
    }
    Path(path).write_text(json.dumps(d, indent=1) + "\n")


def load(path: Path | str) -> np.ndarray:
    """Parameters from a JSON file written by :func:`save` (every name required)."""
    d = json.loads(Path(path).read_text())["params"]
    missing = set(PARAM_NAMES) - set(d)
    extra = set(d) - set(PARAM_NAMES)
    if missing or extra:
        raise ValueError(f"{path}: missing {sorted(missing)}, unknown {sorted(extra)}")
    x = np.array([float(d[k]) for k in PARAM_NAMES])
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{path}: parameters must be finite")
    return x


class ActionMap:
    """Policy action in [-1, 1]^5 -> joint torques [N m], optionally on top of this controller.

    Without a base: ``tau = limit * clip(a, -1, 1)`` (the plain rescaling). With base
    parameters ``x``: ``tau = clip(torques(x, obs) + residual_scale * limit * clip(a, -1, 1))``,
    the policy learning a residual on the controller. The same map serves the batched SB3
    adapter, single envs and the evaluation, so training and evaluation act alike.
    """

    def __init__(self, limit: float, base=None, residual_scale: float = 1.0):
        """Map actions to torques, on top of ``base`` if given.

        ``base``: this controller's parameters (N_PARAMS,), another controller (a callable
        ``base(obs (n, 24), residual=(n, 5))`` returning torques (n, 5), e.g.
        :class:`training.model_controller.ModelController`), or None. ``residual_scale``: the
        residual bound as a fraction of ``limit``, in (0, 1].
        """
        if not (np.isfinite(limit) and limit > 0):
            raise ValueError(f"limit must be finite and > 0, got {limit!r}")
        if not (0 < residual_scale <= 1):
            raise ValueError(f"residual_scale must be in (0, 1], got {residual_scale!r}")
        if base is not None and not callable(base):
            base = np.asarray(base, dtype=np.float64)
            if base.shape != (N_PARAMS,) or not np.all(np.isfinite(base)):
                raise ValueError(f"base must be {N_PARAMS} finite numbers, got {base.shape}")
        self.limit, self.base, self.residual_scale = float(limit), base, float(residual_scale)

    def __call__(self, action: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """Torques (n, 5) for actions (n, 5) and the raw observations (n, 24) they answer."""
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        if self.base is None:
            return a * self.limit
        obs = np.asarray(obs, dtype=np.float64)
        r = self.residual_scale * self.limit * a
        if callable(self.base):  # the controller adds the residual itself (and may project it)
            return np.clip(self.base(obs, residual=r), -self.limit, self.limit)
        tau = torques(self.base, obs, self.limit) + r
        return np.clip(tau, -self.limit, self.limit)


def action_map_from(base_controller: str, residual_scale: float, limit: float) -> ActionMap:
    """The :class:`ActionMap` of a training config.

    ``base_controller``: "" (none), a JSON of this controller's parameters, or ``"model"`` /
    ``"model:GAINS.json"`` for :class:`training.model_controller.ModelController` (default
    gains, or those overridden by the JSON file).
    """
    if base_controller == "model" or base_controller.startswith("model:"):
        from training.model_controller import ModelController

        path = base_controller.partition(":")[2]
        gains = json.loads(Path(path).read_text()) if path else None
        return ActionMap(limit, ModelController(gains, limit=limit), residual_scale)
    base = load(base_controller) if base_controller else None
    return ActionMap(limit, base, residual_scale if base is not None else 1.0)
