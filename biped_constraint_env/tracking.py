"""The tracking task: a reference walk's reward, starts, observation and PD-target actions.

Env options (identical in the single and the batched env, which share one :class:`Tracking`
object per env, with N = 1 for the single env). The reference (:mod:`.reference`) is looked up
on the env's contact clock (:class:`~.clock.ContactClock`: first step from rest, model,
periods since the model began), which restarts at every model switch, so a walk that runs a
little early or late is compared with the reference at the same point of the same contact
phase. The default env uses none of it.

* ``reward="tracking"``: a weighted sum of exponential kernels of the error against the
  reference at the clock, as DeepMimic's: joint angles (theta0 included, wrapped), joint
  rates, hip height and hip forward speed (:data:`TRACKING_WEIGHTS`, which sum to 1, and
  :data:`TRACKING_KERNELS`), plus :data:`TRACKING_STEP_BONUS` per completed step. Every term
  is positive, so ending an episode early never pays; a period ended by an event earns no
  kernel terms. ``info["track_<term>"]`` gives each term (:data:`TRACKING_TERMS`).
* ``rsi`` (reference-state initialisation): that fraction of the resets starts at a recorded
  reference state drawn uniformly (its clock with it); the others draw the env's ``start``.
* ``reference_obs=True``: the reference's q and q-dot at the clock are appended to the
  observation (12 entries, after the phase entries of ``phase_obs``), so that a policy sees
  its target at run time. Without it a policy sees the phase only (``phase_obs``: the
  first-step flag and the time in the model, which with the model one-hot is the clock).
* ``action="pd"``: the action in [-1, 1]^5 sets joint targets
  ``pose + pd_offset + pd_range * a``
  [rad] for q1..q5, where ``pose`` is a fixed pose, ``pd_pose`` (default
  :data:`PD_FIXED_POSE_RAD`; ``pd_around="fixed"``, the default: no reference at run time),
  or the reference's q at the
  clock (``pd_around="reference"``), plus a constant ``pd_offset`` [rad] (default 0; as
  legged-robot RL's default joint offsets); the torques ``Kp (target - q) + Kd (rate - q-dot)``
  (:data:`PD_KP` x ``pd_gain_scale``, :data:`PD_KD` x its square root; ``rate`` is 0 about
  the fixed pose and the reference's q-dot about the reference), clipped to the torque
  limit, are evaluated at every physics step ``pd_dt`` while the targets hold over the
  period (:mod:`.actions`).

Clock: the reference's first step (its recording's first step from its own start) serves the
starts of the same kind, until their first step completes: a start at rest with the rest
reference, a mid-stride start with the mid-stride reference. Any other start is placed on the
gait's phase of its model at the state nearest in q; reference-state starts take their row's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .actions import PD_KD, PD_KP, pd_config
from .clock import ContactClock
from .hybrid import wrap_angles
from .model import N_ACTUATED, N_LINKS
from .reference import REFERENCES, Reference, load_reference
from .starts import draw_starts, start_slots
from .validation import check_array, check_bool, check_choice, check_real

TRACKING_TERMS = ("pose", "velocity", "hip_height", "hip_speed", "step")
"""The tracking reward's terms, in ``info`` as ``track_<term>`` (their sum is the reward)."""
TRACKING_WEIGHTS = {"pose": 0.5, "velocity": 0.1, "hip_height": 0.2, "hip_speed": 0.2}
"""Weights of the kernel terms (they sum to 1: a period on the reference earns 1)."""
TRACKING_KERNELS = {"pose": 5.0, "velocity": 0.05, "hip_height": 200.0, "hip_speed": 5.0}
"""Kernel scales k: term = weight * exp(-k * squared error); the errors are summed over the six
angles for pose [rad^2] and their rates for velocity [(rad/s)^2]; hip height [m^2] and
forward speed [(m/s)^2]. Each halves the term at an error of about: 0.37 rad (one angle),
3.7 rad/s, 59 mm, 0.37 m/s."""
TRACKING_STEP_BONUS = 1.0
"""Reward per completed walking step in the tracking task (a step takes about 170 periods)."""
PD_GAIN_SCALE_MAX = 100.0
PD_RANGE_RAD = 1.0
"""Default half-range of the PD targets around the pose [rad] (``pd_range``)."""
PD_RANGE_MAX_RAD = 3.0
PD_OFFSET_MAX_RAD = 1.0
"""Bound of each ``pd_offset`` entry [rad]."""
PD_FIXED_POSE_RAD = np.array([-0.1, 0.1, -0.3, -0.4, 0.7])
"""The default ``pd_pose`` of ``pd_around="fixed"``: q1..q5 of the Fig. 2 rest posture [rad]."""
ACTIONS = ("torque", "pd")
PD_AROUND = ("fixed", "reference")
REWARDS = ("env", "tracking")


def check_tracking_settings(
    start: str,
    reward,
    reference,
    rsi,
    action,
    pd_around,
    pd_range,
    reference_obs,
    pd_gain_scale=1.0,
    pd_pose=None,
    pd_offset=None,
) -> dict:
    """The validated tracking options of an env (see the module docstring).

    ``reference`` None picks "rest" for ``start`` "rest" or "mixed" (that recording walks the
    first step from rest, then the gait) and "midstride" otherwise.
    """
    out = {
        "reward": check_choice("reward", reward, REWARDS),
        "rsi": check_real("rsi", rsi, 0.0, 1.0),
        "action": check_choice("action", action, ACTIONS),
        "pd_around": check_choice("pd_around", pd_around, PD_AROUND),
        "pd_range": check_real(
            "pd_range", pd_range, 0.0, PD_RANGE_MAX_RAD, low_open=True, unit=" [rad]"
        ),
        "reference_obs": check_bool("reference_obs", reference_obs),
        "pd_gain_scale": check_real(
            "pd_gain_scale", pd_gain_scale, 0.0, PD_GAIN_SCALE_MAX, low_open=True
        ),
        "pd_pose": PD_FIXED_POSE_RAD.copy()
        if pd_pose is None
        else check_array("pd_pose", pd_pose, (N_ACTUATED,), np.pi, " [rad]"),
        "pd_offset": np.zeros(N_ACTUATED)
        if pd_offset is None
        else check_array("pd_offset", pd_offset, (N_ACTUATED,), PD_OFFSET_MAX_RAD, " [rad]"),
    }
    if reference is None:
        reference = "rest" if start in ("rest", "mixed") else "midstride"
    if not isinstance(reference, str) or not (
        reference in REFERENCES or (reference.endswith(".npz") and Path(reference).is_file())
    ):
        raise ValueError(f"reference must be one of {REFERENCES} or an npz path, got {reference!r}")
    out["reference"] = reference
    out["needs_reference"] = (
        out["reward"] == "tracking"
        or out["rsi"] > 0
        or out["reference_obs"]
        or (out["action"] == "pd" and out["pd_around"] == "reference")
    )
    return out


class Tracking:
    """The tracking task's computations for N environments on their contact clock.

    Args:
        n: environments. settings: :func:`check_tracking_settings`. torque_limit_nm: the
            env's torque bound. clock: the env's :class:`~.clock.ContactClock`.
    """

    def __init__(self, n: int, settings: dict, torque_limit_nm: float, clock: ContactClock):
        """Load the reference (when an option needs it) and index its phase tables."""
        self.settings = settings
        self.clock = clock
        self.limit = float(torque_limit_nm)
        self.kp = PD_KP * settings["pd_gain_scale"]
        self.kd = PD_KD * np.sqrt(settings["pd_gain_scale"])
        self.ref: Reference | None = None
        self.first = np.zeros(n, bool)  # in the reference's first step from its own start
        self._per = 1.0  # reference periods per control period (its clock is in its periods)
        if settings["needs_reference"]:
            self.ref = load_reference(settings["reference"])
            self._per = clock.dt / self.ref.dt if clock.dt != self.ref.dt else 1.0
            tables = self.ref.tables
            self._rows = np.concatenate([tables[k] for k in sorted(tables)])
            self._offset = np.zeros((2, 5), np.int64)
            self._len = np.zeros((2, 5), np.int64)
            at = 0
            for k in sorted(tables):
                self._offset[k], self._len[k] = at, len(tables[k])
                at += len(tables[k])
            for m in range(1, 5):  # a phase the first step lacks: the gait's
                if self._len[1, m] == 0:
                    self._offset[1, m], self._len[1, m] = self._offset[0, m], self._len[0, m]

    # ------------------------------------------------------------------ the clock
    def rows(self) -> np.ndarray:
        """(n, 16): the reference's (q, q-dot, hip) at every environment's clock."""
        c = self.clock
        f = self.first.astype(np.int64)
        m = c.mode
        j = c.j if self._per == 1.0 else np.rint(c.j * self._per).astype(np.int64)
        return self._rows[self._offset[f, m] + np.minimum(j, self._len[f, m] - 1)]

    def _env_periods(self, rows: np.ndarray) -> np.ndarray:
        """Reference rows (its periods since a model began) as the env's control periods."""
        return rows if self._per == 1.0 else np.rint(rows / self._per).astype(np.int64)

    def draw_starts(self, params, options, sim, idx, rngs, start, posture, noise) -> None:
        """Start slots ``idx`` (slot ``idx[k]`` drawing from ``rngs[k]``) and their clocks.

        With ``rsi`` > 0 each slot first draws whether it starts at a reference state; the
        others draw the env's ``start`` (:func:`~.starts.draw_starts`). With ``rsi`` = 0 the
        draws are exactly the env's own.
        """
        idx = np.asarray(idx, np.int64)
        rsi = self.settings["rsi"]
        on_ref = np.zeros(idx.shape[0], bool)
        rows = np.zeros(idx.shape[0], np.int64)
        if rsi > 0:
            for k in range(idx.shape[0]):
                if rngs[k].random() < rsi:
                    on_ref[k] = True
                    rows[k] = rngs[k].integers(len(self.ref.q))
        own = np.flatnonzero(~on_ref)
        if own.size:
            draw_starts(
                params, options, sim, idx[own], [rngs[k] for k in own], start, posture, noise
            )
        if on_ref.any():
            ref, r, slots = self.ref, rows[on_ref], idx[on_ref]
            sim.q[slots], sim.qd[slots] = ref.q[r], ref.qd[r]
            start_slots(params, options, sim, slots, ref.mode[r].astype(np.int64))
        self.clock.start(idx, sim.ist[idx, 0], sim.qd[idx])
        # the reference's first step serves the starts of its own kind
        self.first[idx] = self.clock.first[idx] == (self.ref.start == "rest")
        if on_ref.any():
            self.clock.first[slots] = ref.first[r].astype(bool)
            self.clock.j[slots] = self._env_periods(ref.j[r])
            self.first[slots] = ref.step[r] == 0
        self.place(idx[own], sim)

    def start_given(self, idx: np.ndarray, sim) -> None:
        """Clocks of slots ``idx`` started at given states (``reset(options=...)``).

        A start at rest takes the rest reference's first step; any other is placed on the
        gait (:meth:`place`).
        """
        idx = np.asarray(idx, np.int64)
        self.clock.start(idx, sim.ist[idx, 0], sim.qd[idx])
        self.first[idx] = self.clock.first[idx] & (self.ref.start == "rest")
        self.place(idx, sim)

    def after_period(self, steps_after: np.ndarray) -> None:
        """End the reference's first step where a step has completed."""
        self.first &= steps_after == 0

    def place(self, idx: np.ndarray, sim) -> None:
        """Clocks of starts off the reference's first step: the gait's nearest state (in q)."""
        c = self.clock
        idx = np.asarray(idx, np.int64)
        idx = idx[~self.first[idx]]
        for m in np.unique(c.mode[idx]):
            slots = idx[c.mode[idx] == m]
            o, n = self._offset[0, m], self._len[0, m]
            table = self._rows[o : o + n, :N_LINKS]
            d = np.sum((sim.q[slots][:, None, :] - table[None, :, :]) ** 2, axis=2)
            c.j[slots] = self._env_periods(np.argmin(d, axis=1))

    # ------------------------------------------------------------------ actions
    def bases(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(n, 5) bases of the PD targets [rad] and their rates [rad/s] for ``n`` envs.

        The fixed pose plus the offset (rates 0), or the reference's pose at the clock plus
        the offset (its rates); an action a sets the targets base + ``pd_range`` x a, and the
        compiled period applies the PD law to them (:mod:`.actions`).
        """
        offset = self.settings["pd_offset"]
        if self.settings["pd_around"] == "reference":
            rows = self.rows()
            return rows[:, 1:N_LINKS] + offset, rows[:, N_LINKS + 1 : 2 * N_LINKS]
        base = self.settings["pd_pose"] + offset
        return np.broadcast_to(base, (n, N_ACTUATED)), np.zeros((n, N_ACTUATED))

    @property
    def pd_follows_reference(self) -> bool:
        """Whether the PD targets' base moves with the reference (set before every period)."""
        return self.settings["pd_around"] == "reference"

    def pd_config(self, n_sub: int) -> np.ndarray:
        """The compiled period's PD settings (:func:`~.actions.pd_config`) for ``n_sub`` steps."""
        return pd_config(n_sub, self.limit, self.settings["pd_range"], self.kp, self.kd)

    # ------------------------------------------------------------------ observation, reward
    def observation(self) -> np.ndarray:
        """(n, 12): the reference's q and q-dot at the clock (``reference_obs``)."""
        return self.rows()[:, : 2 * N_LINKS]

    def reward(self, q, qd, hip, steps, alive) -> np.ndarray:
        """(n, 6): the tracking terms (:data:`TRACKING_TERMS` order) and their sum.

        For the states after a period against the reference at the clock after it (advance
        the clock first). ``hip`` (n, 4): y, z, vy, vz; ``steps``: steps completed in the
        period; ``alive``: periods not ended by an event (the others earn only their steps).
        """
        ref = self.rows()
        err = (
            np.sum(wrap_angles(q - ref[:, :N_LINKS]) ** 2, axis=1),
            np.sum((qd - ref[:, N_LINKS : 2 * N_LINKS]) ** 2, axis=1),
            (hip[:, 1] - ref[:, 13]) ** 2,
            (hip[:, 2] - ref[:, 14]) ** 2,
        )
        out = np.zeros((q.shape[0], len(TRACKING_TERMS) + 1))
        for c, (name, e) in enumerate(zip(TRACKING_TERMS[:-1], err, strict=True)):
            out[:, c] = TRACKING_WEIGHTS[name] * np.exp(-TRACKING_KERNELS[name] * e)
        out[~alive, :-2] = 0.0
        out[:, -2] = TRACKING_STEP_BONUS * steps
        out[:, -1] = out[:, :-1].sum(axis=1)
        return out
