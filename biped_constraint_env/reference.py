"""Reference motions on a clock synchronised to the contact model.

A reference is a recorded walk (``python -m training.controller.record_reference``: the model-based
teacher, under the default physics and strict checks), kept as plain arrays in an npz file.
It is looked up on the *contact clock* ``(first, mode, j)``:

* ``first``: whether the recording's first step from its own start is still under way (a
  start walks its own first step, then the gait): from rest in the rest reference, from the
  mid-stride start in the mid-stride one (:attr:`Reference.start`);
* ``mode``: the paper's model (1-4) the state is in;
* ``j``: control periods since that model was entered.

Timing drift cannot build up: the clock restarts at every model switch, so a walk that is a
little early or late is compared with the reference's state at the same point of the same
contact phase. Past the end of a phase's recording the lookup holds its last state.

Arrays of an npz (N recorded periods, in order): ``q`` (N, 6) [rad], ``qd`` (N, 6) [rad/s],
``hip`` (N, 4) (y relative to the stance toe, z [m], vy, vz [m/s]), ``mode`` (N,), ``j``
(N,), ``step`` (N,) (completed steps before the period), ``first`` (N,) (1 during the first
step from rest), and the scalars ``dt`` [s] and ``gait_step`` (the completed-step count whose
step is the gait's phase table).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .model import N_LINKS

DATA_DIR = Path(__file__).resolve().parent / "data"
"""Shipped references: ``reference_midstride.npz`` and ``reference_rest.npz``."""
REFERENCES = ("midstride", "rest")
OWN_REFERENCE = "own"
"""``reference="own"``: every start follows the shipped recording of its own kind (a start at
rest the rest recording's first step, a mid-stride start the mid-stride one's); the default
of ``start="mixed"``."""
FIELDS = ("q", "qd", "hip", "mode", "j", "step", "first")
HIP_Y, HIP_Z, HIP_VY, HIP_VZ = range(12, 16)
"""Columns of a phase table's row (q 0-5, q-dot 6-11, then the hip's y, z, vy, vz)."""


@dataclass(frozen=True)
class Reference:
    """A recorded walk and its phase tables (see the module docstring).

    ``table[(first, mode)]`` is the (n_j, 16) array of (q, qd, hip) of that contact phase,
    one row per period since the phase began: the first step's phases (``first`` = 1) from
    the recording's first step (``step`` 0, from its own start), the gait's from the step
    ``gait_step``.
    """

    q: np.ndarray
    qd: np.ndarray
    hip: np.ndarray
    mode: np.ndarray
    j: np.ndarray
    step: np.ndarray
    first: np.ndarray
    dt: float
    gait_step: int

    @property
    def start(self) -> str:
        """The start the recording walks from: "rest" (it begins at rest) or "midstride"."""
        return "rest" if self.first.any() else "midstride"

    @functools.cached_property
    def tables(self) -> dict[tuple[int, int], np.ndarray]:
        """(first, mode) -> (n_j, 16) rows of (q, qd, hip) by periods since the phase began."""
        rows = np.concatenate([self.q, self.qd, self.hip], axis=1)
        out = {}
        for first in (0, 1):
            for mode in (1, 2, 3, 4):
                sel = (self.mode == mode) & (self.step == (0 if first else self.gait_step))
                if sel.any():
                    out[(first, mode)] = rows[sel][np.argsort(self.j[sel], kind="stable")]
        return out

    def lookup(self, first: int, mode: int, j: int) -> np.ndarray:
        """The reference's (q, qd, hip) (16,) at the contact clock (first, mode, j)."""
        t = self.tables.get((int(first), int(mode)))
        if t is None:
            t = self.tables[(0, int(mode))]  # a phase the first step skips: the gait's
        return t[min(int(j), len(t) - 1)]


def load_reference(name_or_path: str | Path) -> Reference:
    """A shipped reference by name (:data:`REFERENCES`) or an npz path (no pickle)."""
    path = Path(name_or_path)
    if str(name_or_path) in REFERENCES:
        path = DATA_DIR / f"reference_{name_or_path}.npz"
    if not path.is_file():
        raise ValueError(f"reference must be one of {REFERENCES} or an npz path, got {path}")
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in FIELDS}
        dt, gait_step = float(z["dt"]), int(z["gait_step"])
    n = len(arrays["q"])
    if arrays["q"].shape != (n, N_LINKS) or arrays["hip"].shape != (n, 4):
        raise ValueError(f"{path}: q must be (N, 6) and hip (N, 4)")
    return Reference(**arrays, dt=dt, gait_step=gait_step)


def save_reference(path: Path, dt: float, gait_step: int, **arrays: np.ndarray) -> None:
    """Write a reference npz (the arrays of :data:`FIELDS`, the period and the gait's step)."""
    missing = set(FIELDS) - set(arrays)
    if missing:
        raise ValueError(f"missing arrays {sorted(missing)}")
    np.savez_compressed(path, dt=dt, gait_step=gait_step, **{k: arrays[k] for k in FIELDS})
