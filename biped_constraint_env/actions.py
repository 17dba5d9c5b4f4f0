"""The action mappings, validated the same way in the single and vector env.

* **Torques** (``action="torque"``): five joint torques [N m], held over the control period.
* **PD targets** (``action="pd"``): five joint targets, held over the control period; the PD
  law ``clip(Kp (target - q) + Kd (rate - q-dot), -limit, limit)`` is evaluated at every
  physics step of ``pd_dt`` inside it (decimation, as legged-robot RL does: the policy
  decides every ``dt``, the joint servo runs every ``pd_dt``), in compiled code
  (:func:`nb_pd_torques`, called by the control period). ``pd_dt = dt`` holds the PD torque
  over the period (the law of earlier versions of the env).

Each mapping is one class of :data:`ACTION_MAPPINGS` (its kind read in this file only): a
mapping computed in Python is a before-period hook (tests/test_parts.py adds one); one at the
physics rate is a kind code of the compiled period and its kernel (:mod:`.period`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .jit import njit_noalloc
from .model import N_ACTUATED, N_LINKS
from .modes import N_MODELS
from .validation import check_array, check_choice, check_mapping, check_real

TORQUE_LIMIT_NM = 150.0
"""Default action bound [N m] (>= 120 so that Table 2 fits)."""
TORQUE_LIMIT_MIN_NM, TORQUE_LIMIT_MAX_NM = 1e-3, 1e6
"""Accepted range of ``torque_limit_nm`` [N m] (the control cost divides by its square)."""


PD_KP = np.array([60.0, 150.0, 150.0, 80.0, 30.0])
"""Proportional gains of the PD-target actions, joints 1..5 [N m / rad] (times
``pd_gain_scale``): a target 1 rad away asks for about the torques the model-based teacher
uses at most (a mid-stride start needs 150 N m at the swing hip at once)."""
PD_KD = np.array([3.0, 8.0, 8.0, 4.0, 1.0])
"""Derivative gains [N m s / rad] (times the square root of ``pd_gain_scale``; on top of
the joints' own damping of 10)."""
PD_DT_S = 0.005
"""Default physics step of the PD law [s] (``pd_dt``): 200 Hz, the walking task's step; a
control period of 20 ms applies its targets through four PD updates."""
PCFG_NSUB, PCFG_LIMIT, PCFG_RANGE, PCFG_KP, PCFG_KD = 0, 1, 2, 3, 3 + N_ACTUATED
"""Entries of :func:`pd_config`'s array: PD updates per period (0: torque actions), the
torque bound [N m], the targets' half-range [rad], Kp (5), Kd (5)."""


MIN_PD_DT_S = 5e-4
"""Shortest PD update period accepted [s] (each update is at least one integration step)."""


def check_pd_dt(pd_dt, dt: float) -> int:
    """PD updates per control period for ``pd_dt`` [s] (None: :data:`PD_DT_S`, at most dt).

    ``dt`` must be a whole multiple of ``pd_dt``.
    """
    if pd_dt is None:
        pd_dt = min(PD_DT_S, dt)
    pd_dt = check_real("pd_dt", pd_dt, min(MIN_PD_DT_S, dt), dt, unit=" [s]")
    n = round(dt / pd_dt)
    if n < 1 or abs(n * pd_dt - dt) > 1e-9 * dt:
        raise ValueError(f"pd_dt must divide the control period dt = {dt} s, got {pd_dt}")
    return int(n)


def pd_config(
    n_sub: int, limit: float, pd_range: float, kp: np.ndarray, kd: np.ndarray
) -> np.ndarray:
    """The PD mapping as one array for the compiled period (``n_sub`` 0: torque actions).

    An action a in [-1, 1]^5 sets the targets ``base + pd_range * a`` [rad] (``base``: the
    pose and offset, or the reference's pose at the clock).
    """
    return np.array([float(n_sub), float(limit), float(pd_range), *kp, *kd], dtype=np.float64)


TORQUE_ACTIONS = pd_config(0, 0.0, 0.0, np.zeros(N_ACTUATED), np.zeros(N_ACTUATED))
"""The :func:`pd_config` of torque actions (no PD law)."""


@njit_noalloc
def nb_pd_targets(base, action, pcfg, target) -> None:
    """The PD targets: target (5,) = base + pd_range * clip(action, -1, 1) [rad]."""
    r = pcfg[PCFG_RANGE]
    for j in range(N_ACTUATED):
        target[j] = base[j] + r * min(max(action[j], -1.0), 1.0)


@njit_noalloc
def nb_pd_torques(target, rate, q, qd, pcfg, tau) -> None:
    """The PD torques: tau (5,) = clip(Kp (target - q[1:]) + Kd (rate - qd[1:]), +-limit)."""
    limit = pcfg[PCFG_LIMIT]
    for j in range(N_ACTUATED):
        x = pcfg[PCFG_KP + j] * (target[j] - q[j + 1]) + pcfg[PCFG_KD + j] * (rate[j] - qd[j + 1])
        tau[j] = min(max(x, -limit), limit)


PD_BOUND = "PD-target bound"
"""``bound`` of :func:`validate_actions` for PD-target actions (limit 1, no unit)."""


def validate_actions(
    actions: Any, limit: float, out_of_range: str, bound: str = "torque limit"
) -> np.ndarray:
    """(..., 5) float64 torques [N m]; ValueError on NaN/inf/shape/dtype/range (as documented).

    ``bound`` names the limit in the messages (:data:`PD_BOUND` for PD-target actions).
    """
    a = actions if isinstance(actions, np.ndarray) else np.asarray(actions)
    if a.shape[-1:] != (N_ACTUATED,):
        raise ValueError(f"action must have shape ({N_ACTUATED},), got {a.shape}")
    if a.dtype.kind not in "fiu":
        raise ValueError(f"action must be real numbers, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if a.ndim == 1:  # a comparison with NaN is False, so this screens NaN, inf and range
        inside = all(-limit <= x <= limit for x in a.tolist())
    else:
        inside = np.abs(a).max() <= limit  # NaN propagates through max
    if not inside:
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a}")
        if out_of_range == "raise":
            unit = " N m" if bound == "torque limit" else ""
            raise ValueError(f"action {a} exceeds the {bound} +-{limit}{unit}")
        a = np.clip(a, -limit, limit)
    return a


def validate_action(
    action: Any, limit: float, out_of_range: str, bound: str = "torque limit"
) -> np.ndarray:
    """(5,) float64 torques [N m] from one action (see :func:`validate_actions`)."""
    a = action if isinstance(action, np.ndarray) else np.asarray(action)
    if a.shape != (N_ACTUATED,):
        raise ValueError(f"action must have shape ({N_ACTUATED},), got {a.shape}")
    if a.dtype.kind == "f":  # the common case, checked with Python floats (fastest for 5)
        a64 = a.astype(np.float64)
        if all(-limit <= x <= limit for x in a64.tolist()):  # False for NaN: screens it too
            return a64
    return validate_actions(a, limit, out_of_range, bound)


def check_action_settings(torque_limit_nm: float, out_of_range: str) -> tuple[float, str]:
    """The validated torque limit [N m] and out-of-range policy of an env."""
    limit = check_real(
        "torque_limit_nm", torque_limit_nm, TORQUE_LIMIT_MIN_NM, TORQUE_LIMIT_MAX_NM, unit=" [N m]"
    )
    return limit, check_choice("out_of_range", out_of_range, ("clip", "raise"))


def action_config(limit: float, out_of_range: str) -> np.ndarray:
    """[limit, clip] for :func:`nb_check_torques`: the bound [N m], 1.0 to clip (0.0: raise)."""
    return np.array([limit, 1.0 if out_of_range == "clip" else 0.0])


@njit_noalloc
def nb_check_torques(ACT, acfg) -> int:
    """The compiled twin of :func:`validate_actions` on float64 actions (n, 5), in place.

    Returns 0 when every torque is finite and, with ``acfg[1] == 1``, clips it to
    ``[-acfg[0], acfg[0]]``; returns 1 (the caller raises through :func:`validate_action`)
    on a NaN or inf, or on a torque beyond the bound when clipping is off.
    """
    limit = acfg[0]
    clip = acfg[1] != 0.0
    for i in range(ACT.shape[0]):
        for j in range(ACT.shape[1]):
            x = ACT[i, j]
            if not np.isfinite(x):
                return 1
            if x > limit or x < -limit:
                if not clip:
                    return 1
                ACT[i, j] = min(max(x, -limit), limit)
    return 0


# ----------------------------------------------------------------------------- settings
PD_RANGE_RAD = 1.0
"""Default half-range of the PD targets around their base [rad] (``action["range"]``)."""
PD_RANGE_MAX_RAD = 3.0
PD_OFFSET_MAX_RAD = 1.0
"""Bound of each ``action["offset"]`` entry [rad]."""
PD_GAIN_SCALE_MAX = 100.0
PD_FIXED_POSE_RAD = (-0.1, 0.1, -0.3, -0.4, 0.7)
"""The default ``action["pose"]`` of ``around="fixed"``: q1..q5 of the Fig. 2 rest posture."""
PD_AROUND = ("fixed", "reference")
PD_KEYS = ("kind", "around", "range", "pose", "offset", "gain_scale", "dt")
"""The ``action`` dict's PD keys (all but ``kind`` are the PD mapping's)."""
ACTION_KEYS = PD_KEYS + ("torque_limit_nm", "out_of_range")
"""Keys of the ``action`` dict: the kind, the torque limit [N m] and what an out-of-range action
does (every kind), and the PD mapping's."""


@dataclass(frozen=True)
class ActionSettings:
    """The action mapping: torques [N m], or PD targets in [-1, 1]^5 about a base.

    PD targets ``base + offset + range * a`` hold over the control period; the law
    ``Kp (target - q) + Kd (rate - q-dot)`` (``PD_KP`` x ``gain_scale``, ``PD_KD`` x its
    square root), clipped to ``torque_limit_nm``, runs ``pd_substeps`` times in it.
    """

    kind: str
    torque_limit_nm: float
    out_of_range: str
    around: str = "fixed"
    range: float = PD_RANGE_RAD
    pose: tuple[float, ...] = PD_FIXED_POSE_RAD
    offset: tuple[tuple[float, ...], ...] = ((0.0,) * N_ACTUATED,) * N_MODELS
    gain_scale: float = 1.0
    pd_substeps: int = 0

    @property
    def pd(self) -> bool:
        """Whether the actions are PD targets."""
        return self.kind == "pd"

    @property
    def unit_actions(self) -> bool:
        """Whether an action is a point of [-1, 1]^5 that the env maps (PD targets)."""
        return ACTION_MAPPINGS[self.kind].unit_actions

    @property
    def needs_reference(self) -> bool:
        """Whether the mapping reads the reference walk (PD targets about its pose)."""
        return self.pd and self.around == "reference"

    @property
    def bases_vary(self) -> bool:
        """Whether the PD targets' bases change in an episode (set before every period).

        They do about the reference, or with offsets that differ between the models.
        """
        return self.pd and (self.around == "reference" or self.offset_by_model)

    def in_the_loop(self) -> str:
        """What acts at run time with this mapping, after the network."""
        return ACTION_MAPPINGS[self.kind].in_the_loop(self)

    @property
    def offset_by_model(self) -> bool:
        """Whether the targets' offset differs between the models."""
        return len(set(self.offset)) > 1

    @property
    def bound(self) -> float:
        """The action space's bound: 1 for unit actions (PD targets), else the torque limit."""
        return 1.0 if self.unit_actions else self.torque_limit_nm

    @property
    def bound_name(self) -> str:
        """The bound's name in error messages."""
        return ACTION_MAPPINGS[self.kind].bound_name

    @property
    def kp(self) -> np.ndarray:
        """The proportional gains [N m / rad]."""
        return PD_KP * self.gain_scale

    @property
    def kd(self) -> np.ndarray:
        """The derivative gains [N m s / rad]."""
        return PD_KD * np.sqrt(self.gain_scale)


def action_settings(spec: Any, task_spec: Any, dt: float) -> ActionSettings:
    """The ``action`` kwarg (a kind, or a dict of :data:`ACTION_KEYS`) on top of the task's."""

    def as_dict(x):
        return {"kind": x} if isinstance(x, str) else dict(check_mapping("action", x, ACTION_KEYS))

    task = as_dict(task_spec)
    given = {} if spec is None else as_dict(spec)
    kind = check_choice("action kind", given.get("kind", task.get("kind", "torque")),
                        tuple(ACTION_MAPPINGS))  # fmt: skip
    merged = {**(task if task.get("kind", "torque") == kind else {}), **given, "kind": kind}
    limit, out_of_range = check_action_settings(merged.get("torque_limit_nm", TORQUE_LIMIT_NM),
                                                merged.get("out_of_range", "clip"))  # fmt: skip
    if kind != "pd":
        extra = sorted(set(given) - {"kind", "torque_limit_nm", "out_of_range"})
        if extra:
            raise ValueError(f"action: {extra} are PD settings; {kind} actions take none")
        return ActionSettings(kind, limit, out_of_range)
    pose = merged.get("pose")
    offset = merged.get("offset")
    scale = check_real("action gain_scale", merged.get("gain_scale", 1.0), 0.0,
                       PD_GAIN_SCALE_MAX, low_open=True)  # fmt: skip
    return ActionSettings(
        kind="pd",
        torque_limit_nm=limit,
        out_of_range=out_of_range,
        around=check_choice("action around", merged.get("around", "fixed"), PD_AROUND),
        range=check_real(
            "action range",
            merged.get("range", PD_RANGE_RAD),
            0.0,
            PD_RANGE_MAX_RAD,
            low_open=True,
            unit=" [rad]",
        ),  # fmt: skip
        pose=PD_FIXED_POSE_RAD
        if pose is None
        else tuple(check_array("action pose", pose, (N_ACTUATED,), np.pi, " [rad]").tolist()),
        offset=_offsets(offset),
        gain_scale=scale,
        pd_substeps=check_pd_dt(merged.get("dt"), dt),
    )


def _offsets(offset: Any) -> tuple[tuple[float, ...], ...]:
    """``action["offset"]``: q1..q5 [rad] in every model, or one row per model (4 x 5)."""
    if offset is None:
        return ((0.0,) * N_ACTUATED,) * N_MODELS
    try:
        nested = np.ndim(offset) == 2
    except ValueError:  # ragged: check_array names it
        nested = False
    shape = (N_MODELS, N_ACTUATED) if nested else (N_ACTUATED,)
    rows = check_array("action offset", offset, shape, PD_OFFSET_MAX_RAD, " [rad]")
    rows = np.broadcast_to(rows, (N_MODELS, N_ACTUATED))
    return tuple(tuple(r.tolist()) for r in rows)


# ----------------------------------------------------------------------------- the part
class TorqueActions:
    """``action="torque"``: the actions are the torques [N m] (the compiled period's kind 0).

    An action mapping is one class of :data:`ACTION_MAPPINGS`: what it is to a user
    (``unit_actions``: a point of [-1, 1]^5; ``bound_name``; :meth:`in_the_loop`) and, per
    env, its part: ``pcfg`` (the compiled period's kind code and PD law:
    :func:`pd_config`), ``check_bound`` (the bound the compiled period checks ``act``
    against), ``info_keys``, :meth:`hooks` (what runs before a period: the actions to what
    ``act`` holds), :meth:`info` and :meth:`clear`. A mapping computed in Python is a hook; a
    mapping at the physics rate is a kind code and its kernel (:mod:`.period`).
    """

    unit_actions = False
    bound_name = "torque limit"
    holds_torques = True
    """Whether ``act`` holds the period's torques themselves (False: the PD law makes them)."""

    def __init__(self, action: ActionSettings, n: int, reference=None):
        """For the validated ``action`` and ``n`` rows (``reference``: unused)."""
        self.action = action
        self.pcfg = TORQUE_ACTIONS
        self.check_bound = action.torque_limit_nm
        self.info_keys: tuple[str, ...] = ()

    @staticmethod
    def in_the_loop(action: ActionSettings) -> str:
        """What acts at run time with this mapping, after the network."""
        return "network alone (torques)"

    def hooks(self, buf, sim_modes) -> list:
        """Before-period hooks fn(actions, rngs, rows) -> actions: none."""
        return []

    def info(self, buf, row):
        """``info`` values of :attr:`info_keys`: none."""
        return ()

    def clear(self, buf) -> None:
        """After a reset: nothing to clear."""


class PDTargets(TorqueActions):
    """``action="pd"``: PD targets in [-1, 1]^5 about a base (the compiled period's PD kind).

    The compiled period's config, the targets' bases (set once about a fixed pose, or before
    every period about the reference at the clock), ``info["torque"]`` and a cleared action
    at reset. ``reference``: the rows' reference lookup (:class:`~.tracking.Tracking`:
    ``rows()``, the reference at each row's clock), needed only about the reference.
    """

    unit_actions = True
    holds_torques = False
    bound_name = PD_BOUND

    def __init__(self, action: ActionSettings, n: int, reference=None):
        """For the validated ``action`` and ``n`` rows."""
        self.action, self.reference = action, reference
        self._offset = np.array(action.offset, dtype=np.float64)  # (4, 5), by model
        self.pcfg = pd_config(action.pd_substeps, action.torque_limit_nm, action.range,
                              action.kp, action.kd)  # fmt: skip
        self.check_bound = 1.0
        self.info_keys = ("torque",)

    @staticmethod
    def in_the_loop(action: ActionSettings) -> str:
        """What acts at run time with this mapping, after the network."""
        if action.needs_reference:
            return "network + PD about the reference pose at the contact clock"
        return "network alone (PD targets about a fixed pose)"

    def bases(self, modes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 5) bases of the PD targets [rad] and their rates [rad/s] of rows in ``modes``.

        The fixed pose plus the offset of the row's model (rates 0), or the reference's pose
        at the clock plus that offset (its rates); an action a sets the targets base +
        ``range`` x a, and the compiled period applies the PD law to them.
        """
        offset = self._offset[np.asarray(modes) - 1]
        if self.action.around == "reference":
            rows = self.reference.rows()
            return rows[:, 1:N_LINKS] + offset, rows[:, N_LINKS + 1 : 2 * N_LINKS]
        return np.array(self.action.pose) + offset, np.zeros((len(offset), N_ACTUATED))

    def hooks(self, buf, sim_modes) -> list:
        """Before-period hooks: the bases where they vary (set once here where they do not)."""
        if not self.action.bases_vary:  # constant bases about a fixed pose: set once
            buf.tgt[:], buf.rate[:] = self.bases(np.ones(buf.tgt.shape[0], np.int64))
            return []

        def pd_bases(actions, rngs, rows):  # the targets' bases at the clocks and models
            buf.tgt[:], buf.rate[:] = self.bases(sim_modes())
            return actions

        return [pd_bases]

    def info(self, buf, row):
        """``info`` values of :attr:`info_keys`: the period's time-mean PD torque."""
        return (buf.act[row].copy() if row is not None else buf.act.copy(),)

    def clear(self, buf) -> None:
        """After a reset: no torque of a period yet (PD targets' ``info["torque"]``)."""
        buf.act[:] = 0.0


ACTION_MAPPINGS: dict[str, type[TorqueActions]] = {"torque": TorqueActions, "pd": PDTargets}
"""The action mappings by kind (``action=`` names one): a new mapping is one entry here (and,
at the physics rate, its kernel in :mod:`.period`)."""


def action_part(action: ActionSettings, n: int, reference=None) -> TorqueActions:
    """The part of ``n`` rows for the validated ``action`` (the kind read here only)."""
    return ACTION_MAPPINGS[action.kind](action, n, reference)
