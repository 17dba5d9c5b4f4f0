"""The paper's four models as data, and the named events that leave them.

One walking step is the cycle 1 -> 2 -> 3 -> 4 -> 1. Each model differs only in which joint is
free (``theta0``), which point contact is active, which guard ends it, what follows, and which
reset map applies on entry to the successor. The physics (one Jacobian routine, one
constrained solve) is shared by all four.

Guard sign convention (used everywhere): a guard is a signed float in SI units that is
**positive while the state is inside the model**. A transition guard fires at ``<= 0``;
an out-of-model guard fires at ``< 0`` (geometric ones carry a penetration tolerance).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from types import MappingProxyType

import numpy as np

from .contact import OLD_STANCE_TOE, SWING_HEEL, PointContact


class Mode(IntEnum):
    """The paper's models, numbered as in the paper (used in observations, info and plots)."""

    FOOT_FLAT = 1
    """Model 1: stance foot flat, swing leg free; unknowns q1..q5."""
    TOE_PIVOT = 2
    """Model 2: stance foot pivots on its toe, swing leg free; unknowns q0..q5."""
    TOE_HEEL = 3
    """Model 3: stance toe + swing heel point contact; unknowns q0..q5, f_n."""
    DOUBLE_SUPPORT = 4
    """Model 4: new stance foot flat (chain renumbered) + old toe point contact; q1..q5, f_n."""


class Guard(IntEnum):
    """Which quantity ends a model (its transition guard), in SI units."""

    HEEL_FORCE = 0
    """F_L [N], the stance heel's share of the ankle force and moment (paper eq. 16-20)."""
    SWING_HEEL_HEIGHT = 1
    """z of the swing heel [m] (paper eq. 22)."""
    SWING_FOOT_ANGLE = 2
    """phi5, the swing foot's angle to the ground [rad] (paper eq. 24)."""
    CONTACT_FORCE = 3
    """f_n, the old toe's normal force [N] (paper eq. 31)."""


class Reset(IntEnum):
    """The reset map applied on entering the successor."""

    NONE = 0
    """Continuous: the state carries over (1 -> 2, 4 -> 1)."""
    HEEL_STRIKE = 1
    """Impact at the swing heel (2 -> 3)."""
    FOOT_FLAT_RENUMBER = 2
    """Impact bringing the swing foot flat, then the chain renumbering (3 -> 4, eq. 25-29)."""


@dataclass(frozen=True)
class ModeSpec:
    """One row of the mode table.

    Attributes:
        root_joint_free: whether theta0 (the toe pivot) is an unknown.
        contact: the active point contact, if any.
        guard: the transition guard.
        successor: the next model.
        reset: the reset map on entering the successor.
    """

    root_joint_free: bool
    contact: PointContact | None
    guard: Guard
    successor: Mode
    reset: Reset

    @property
    def n_unknowns(self) -> int:
        """Unknowns of the model's linear system (paper eq. 15, 21, 23, 30)."""
        return (6 if self.root_joint_free else 5) + (1 if self.contact is not None else 0)


MODE_TABLE = MappingProxyType(
    {
        Mode.FOOT_FLAT: ModeSpec(False, None, Guard.HEEL_FORCE, Mode.TOE_PIVOT, Reset.NONE),
        Mode.TOE_PIVOT: ModeSpec(
            True, None, Guard.SWING_HEEL_HEIGHT, Mode.TOE_HEEL, Reset.HEEL_STRIKE
        ),
        Mode.TOE_HEEL: ModeSpec(
            True, SWING_HEEL, Guard.SWING_FOOT_ANGLE, Mode.DOUBLE_SUPPORT, Reset.FOOT_FLAT_RENUMBER
        ),
        Mode.DOUBLE_SUPPORT: ModeSpec(
            False, OLD_STANCE_TOE, Guard.CONTACT_FORCE, Mode.FOOT_FLAT, Reset.NONE
        ),
    }
)
"""The four models (paper section 3)."""
N_MODELS = len(MODE_TABLE)
"""The paper's models (1-4): settings given one value per model have this many."""


class EventCode(IntEnum):
    """Named events of the hybrid simulator. 0 is a model switch; the rest leave the model."""

    MODE_SWITCH = 0
    STANCE_FOOT_TIPS_BACK = 1
    """Model 1: toe force F_R <= 0, the stance foot would tip backwards about its heel."""
    STANCE_HEEL_DOWN = 2
    """Models 2-4: a pivoting foot's heel (stance, or the old stance in model 4) below ground."""
    SWING_TOE_STRIKE = 3
    """Model 2: the swing toe reaches the ground before the heel."""
    SWING_FOOT_TOUCHDOWN = 4
    """Model 1: the swing foot (heel or toe) touches the ground."""
    BODY_BELOW_GROUND = 5
    """A knee or the hip below the ground (an ankle, the midpoint of its foot's sole, can only
    go below through a foot end, which the foot guards report)."""
    SWING_HEEL_PULLS = 6
    """Model 3: the heel contact would have to pull (f_n < 0)."""
    STANCE_TOE_PULLS = 7
    """Models 2-3: the stance toe's vertical force < 0."""
    STANCE_FOOT_PULLS = 8
    """Model 4: either end of the new stance foot would have to pull."""
    STEP_BEHIND_STANCE_TOE = 9
    """Model 2 -> 3: the swing heel lands behind the stance toe."""
    ZENO = 10
    """Too many model switches within one control period (chattering)."""
    NON_FINITE = 11
    """The state became non-finite (the simulator raises SimulationError)."""


FORCE_EVENTS = frozenset(
    {
        EventCode.STANCE_FOOT_TIPS_BACK,
        EventCode.SWING_HEEL_PULLS,
        EventCode.STANCE_TOE_PULLS,
        EventCode.STANCE_FOOT_PULLS,
    }
)
"""Events that only ``strict`` checking ends a run on; ``lenient`` records them and goes on."""

N_GUARDS = 9
"""Guard vector length: index 0 is the transition guard, 1..8 the EventCode of the same value."""


def packed_mode_table() -> tuple[np.ndarray, ...]:
    """Arrays (indexed by mode number 1..4) for the compiled core.

    Returns root_free (5,) int, contact offset column (5,) int (-1 none), guard (5,) int,
    successor (5,) int, reset (5,) int.
    """
    root_free = np.zeros(5, np.int64)
    contact = -np.ones(5, np.int64)
    guard = np.zeros(5, np.int64)
    succ = np.zeros(5, np.int64)
    reset = np.zeros(5, np.int64)
    for mode, spec in MODE_TABLE.items():
        root_free[mode] = spec.root_joint_free
        contact[mode] = -1 if spec.contact is None else int(spec.contact.end)
        guard[mode] = spec.guard
        succ[mode] = spec.successor
        reset[mode] = spec.reset
    return root_free, contact, guard, succ, reset
