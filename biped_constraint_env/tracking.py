"""The tracking task: a reference walk's reward, starts, observation and PD-target actions.

Env options (identical in the single and the batched env, which share one :class:`Tracking`
object per env, with N = 1 for the single env). The reference (:mod:`.reference`) is looked up
on the env's contact clock (:class:`~.clock.ContactClock`: first step from rest, model,
periods since the model began), which restarts at every model switch, so a walk that runs a
little early or late is compared with the reference at the same point of the same contact
phase. The default env uses none of it.

* ``reward="tracking"``: a weighted sum of exponential kernels of the error against the
  reference at the clock, as DeepMimic's: joint angles (theta0 included, wrapped), joint
  rates, hip height and hip forward speed, plus a bonus per completed step (weights and
  kernels: :data:`~.rewards.REWARD_KINDS`). Every term is positive, so ending an episode
  early never pays; a period ended by an event earns no kernel terms. ``info["reward_<term>"]``
  gives each term.
* ``start={"kind": {"reference": w, ...}}`` (reference-state initialisation): the fraction w
  of the resets starts at a recorded reference state drawn uniformly (its clock with it); the
  others draw the start's other components.
* A policy sees the phase only (``phase_obs``: the first-step flag and the time in the
  model, which with the model one-hot is the clock), never the reference itself.
* ``action={"kind": "pd", ...}``: the action in [-1, 1]^5 sets joint targets
  ``base + offset + range * a`` [rad] for q1..q5, where ``base`` is a fixed ``pose``
  (``around="fixed"``, the default: no reference at run time) or the reference's q at the
  clock (``around="reference"``), plus a constant ``offset`` [rad] (as legged-robot RL's
  default joint offsets); the PD law runs at every physics step while the targets hold over
  the period (:mod:`.actions`, :class:`~.actions.ActionSettings`).

Clock: the reference's first step (its recording's first step from its own start) serves the
starts of the same kind, until their first step completes: a start at rest with the rest
reference, a mid-stride start with the mid-stride reference. Any other start is placed on the
gait's phase of its model at the state nearest in q; reference-state starts take their row's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .clock import ContactClock
from .hybrid import wrap_angles
from .model import N_LINKS
from .reference import (
    HIP_VY,
    HIP_Z,
    OWN_REFERENCE,
    REFERENCES,
    Reference,
    load_reference,
)
from .starts import draw_starts, split_reference, start_slots
from .state import ST_MODE

if TYPE_CHECKING:
    from .settings import EnvSettings

KERNEL_ERRORS = ("pose", "velocity", "hip_height", "hip_speed")
"""The tracking reward's kernel terms (:data:`~.rewards.REWARD_KINDS` ``"tracking"``), in the
order :meth:`Tracking.reward` computes their errors."""


class Tracking:
    """The tracking task's computations for N environments on their contact clock.

    Args:
        n: environments. settings: the env's :class:`~.settings.EnvSettings`. clock: the
            env's :class:`~.clock.ContactClock` (None when no option needs the reference).
    """

    def __init__(self, n: int, settings: EnvSettings, clock: ContactClock | None):
        """Load the reference (when an option needs it) and index its phase tables."""
        self.settings = settings
        self.clock = clock
        self.refs: list[Reference] = []
        self.which = np.zeros(n, np.int64)  # each env's reference (an index into refs)
        self.first = np.zeros(n, bool)  # in the reference's first step from its own start
        self._per = 1.0  # reference periods per control period (its clock is in its periods)
        r = settings.reward
        if r.kind == "tracking":
            self._w = np.array([r.weight(t) for t in KERNEL_ERRORS])
            self._k = np.array([r.kernel(t) for t in KERNEL_ERRORS])
            self._step_bonus = r.weight("step")
        if settings.needs_reference:
            names = REFERENCES if settings.reference == OWN_REFERENCE else (settings.reference,)
            self.refs = [load_reference(name) for name in names]
            if len({ref.dt for ref in self.refs}) > 1:
                raise ValueError("the references of reference='own' must share their dt")
            self._per = clock.dt / self.refs[0].dt if clock.dt != self.refs[0].dt else 1.0
            self._rest = next((i for i, ref in enumerate(self.refs) if ref.start == "rest"), -1)
            self._index_tables()

    @property
    def ref(self) -> Reference | None:
        """The (first) reference walk, None when no option reads one."""
        return self.refs[0] if self.refs else None

    def _index_tables(self) -> None:
        """One array of every reference's phase tables; offsets and lengths by (ref, first, mode).

        A phase the first step lacks takes the gait's.
        """
        parts = []
        self._offset = np.zeros((len(self.refs), 2, 5), np.int64)
        self._len = np.zeros((len(self.refs), 2, 5), np.int64)
        at = 0
        for r, ref in enumerate(self.refs):
            tables = ref.tables
            for k in sorted(tables):
                self._offset[(r, *k)], self._len[(r, *k)] = at, len(tables[k])
                at += len(tables[k])
                parts.append(tables[k])
            for m in range(1, 5):
                if self._len[r, 1, m] == 0:
                    self._offset[r, 1, m], self._len[r, 1, m] = (self._offset[r, 0, m],
                                                                 self._len[r, 0, m])  # fmt: skip
        self._rows = np.concatenate(parts)

    # ------------------------------------------------------------------ the clock
    def rows(self) -> np.ndarray:
        """(n, 16): each env's reference's (q, q-dot, hip) at its clock."""
        c = self.clock
        f = self.first.astype(np.int64)
        m, w = c.mode, self.which
        j = c.j if self._per == 1.0 else np.rint(c.j * self._per).astype(np.int64)
        return self._rows[self._offset[w, f, m] + np.minimum(j, self._len[w, f, m] - 1)]

    def _env_periods(self, rows: np.ndarray) -> np.ndarray:
        """Reference rows (its periods since a model began) as the env's control periods."""
        return rows if self._per == 1.0 else np.rint(rows / self._per).astype(np.int64)

    def _own(self, idx: np.ndarray) -> None:
        """Each env of ``idx`` takes the reference of its start's kind (its clock started).

        A start at rest the rest recording's, any other the other one (with one reference:
        that one); it is in that reference's first step when the kinds match.
        """
        at_rest = self.clock.first[idx]
        if len(self.refs) > 1:
            self.which[idx] = np.where(at_rest, self._rest, 1 - self._rest)
        self.first[idx] = at_rest == (self.refs[0].start == "rest") if len(self.refs) == 1 \
            else True  # fmt: skip

    def draw_starts(self, params, options, sim, idx, rngs, start, posture, noise) -> None:
        """Start slots ``idx`` (slot ``idx[k]`` drawing from ``rngs[k]``) and their clocks.

        The start's ``"reference"`` component (:data:`~.starts.REFERENCE_START`, weight w)
        draws first: each slot draws whether it starts at a reference state (u < w; with two
        references, then which; then the row, uniformly); the others draw the start's other
        components (:func:`~.starts.split_reference`, :func:`~.starts.draw_starts`). Without
        the component the draws are exactly the env's own.
        """
        idx = np.asarray(idx, np.int64)
        weight, start = split_reference(start)
        on_ref = np.zeros(idx.shape[0], bool)
        rows = np.zeros(idx.shape[0], np.int64)
        refs = np.zeros(idx.shape[0], np.int64)
        if weight > 0:
            for k in range(idx.shape[0]):
                if rngs[k].random() < weight:
                    on_ref[k] = True
                    if len(self.refs) > 1:
                        refs[k] = rngs[k].integers(len(self.refs))
                    rows[k] = rngs[k].integers(len(self.refs[refs[k]].q))
        own = np.flatnonzero(~on_ref)
        if own.size:
            draw_starts(
                params, options, sim, idx[own], [rngs[k] for k in own], start, posture, noise
            )
        for r in np.unique(refs[on_ref]):
            k = on_ref & (refs == r)
            ref, rr, slots = self.refs[r], rows[k], idx[k]
            sim.q[slots], sim.qd[slots] = ref.q[rr], ref.qd[rr]
            start_slots(params, options, sim, slots, ref.mode[rr].astype(np.int64))
        self.clock.start(idx, sim.ist[idx, ST_MODE], sim.qd[idx])
        self._own(idx)  # the reference's first step serves the starts of its own kind
        for r in np.unique(refs[on_ref]):
            k = on_ref & (refs == r)
            ref, rr, slots = self.refs[r], rows[k], idx[k]
            self.which[slots] = r
            self.clock.first[slots] = ref.first[rr].astype(bool)
            self.clock.j[slots] = self._env_periods(ref.j[rr])
            self.clock.opening[slots] &= ref.j[rr] == 0  # mid-phase: not a phase's start
            self.first[slots] = ref.step[rr] == 0
        self.place(idx[own], sim)

    def start_given(self, idx: np.ndarray, sim) -> None:
        """Clocks of slots ``idx`` started at given states (``reset(options=...)``).

        A start at rest takes the rest reference's first step; any other is placed on the
        gait (:meth:`place`).
        """
        idx = np.asarray(idx, np.int64)
        self.clock.start(idx, sim.ist[idx, ST_MODE], sim.qd[idx])
        self._own(idx)
        self.first[idx] &= self.clock.first[idx]  # only a start at rest is on a first step
        self.place(idx, sim)

    def after_period(self, steps_after: np.ndarray) -> None:
        """End the reference's first step where a step has completed."""
        self.first &= steps_after == 0

    def place(self, idx: np.ndarray, sim) -> None:
        """Clocks of starts off the reference's first step: the gait's nearest state (in q)."""
        c = self.clock
        idx = np.asarray(idx, np.int64)
        idx = idx[~self.first[idx]]
        for w in np.unique(self.which[idx]):
            at = idx[self.which[idx] == w]
            for m in np.unique(c.mode[at]):
                slots = at[c.mode[at] == m]
                o, n = self._offset[w, 0, m], self._len[w, 0, m]
                table = self._rows[o : o + n, :N_LINKS]
                d = np.sum((sim.q[slots][:, None, :] - table[None, :, :]) ** 2, axis=2)
                c.j[slots] = self._env_periods(np.argmin(d, axis=1))

    # ------------------------------------------------------------------ observation, reward
    def reward(self, q, qd, hip, steps, alive) -> np.ndarray:
        """(n, 6): the tracking reward's terms (the registry's order) and their sum.

        For the states after a period against the reference at the clock after it (advance
        the clock first). ``hip`` (n, 4): y, z, vy, vz; ``steps``: steps completed in the
        period; ``alive``: periods not ended by an event (the others earn only their steps).
        """
        ref = self.rows()
        err = (
            np.sum(wrap_angles(q - ref[:, :N_LINKS]) ** 2, axis=1),
            np.sum((qd - ref[:, N_LINKS : 2 * N_LINKS]) ** 2, axis=1),
            (hip[:, 1] - ref[:, HIP_Z]) ** 2,
            (hip[:, 2] - ref[:, HIP_VY]) ** 2,
        )
        out = np.zeros((q.shape[0], len(KERNEL_ERRORS) + 2))
        for c, e in enumerate(err):
            out[:, c] = self._w[c] * np.exp(-self._k[c] * e)
        out[~alive, :-2] = 0.0
        out[:, -2] = self._step_bonus * steps
        out[:, -1] = out[:, :-1].sum(axis=1)
        return out
