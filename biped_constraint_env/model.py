"""Model parameters: frozen, validated, SI units (paper Table 1).

The biped is a planar serial chain of six uniform rods (docs/conventions.md):

====  ==============  =====================================================
link  name            geometry (chain rooted at the stance toe)
====  ==============  =====================================================
0     stance foot     heel -> toe bar; joint 0 (passive pivot) at the toe,
                      ankle (joint 1) and centre of mass at the midpoint
1     stance shank    ankle -> knee
2     stance thigh    knee -> hip
3     swing thigh     hip -> knee
4     swing shank     knee -> ankle
5     swing foot      heel -> toe bar; ankle (joint 5) and centre of mass at the midpoint
====  ==============  =====================================================

:class:`BipedParams` holds the physical robot in the paper's numbering (leg A stands).
:func:`chain_for` returns the :class:`ChainModel` for either numbering: the chain renumbering at
model 3 -> 4 (paper eq. 25-29) is a *different value* (the links reversed), never a flag.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from .units import G_MPS2, HALF_PI_RAD, PI_RAD

N_LINKS = 6
"""Links in the chain (stance foot, two shanks, two thighs, swing foot)."""

N_ACTUATED = 5
"""Actuated joints 1..5 (joint 0, the toe pivot, is passive)."""

# Column layout of the packed chain array used by the compiled core (see ChainModel.packed).
COL_MASS, COL_INERTIA, COL_COM, COL_NEXT, COL_ANGLE, COL_DAMPING = range(6)
N_COLS = 6
# Layout of the packed scalar array (see ChainModel.packed_scalars).
(SC_GRAVITY, SC_FRICTION, SC_SPLIT, SC_HEEL0, SC_HEEL5, SC_TOE5, SC_FOOT0_MASS,
 SC_GRAVITY_T) = range(8)  # fmt: skip
N_SCALARS = 8
MAX_SLOPE_RAD = 0.35
"""Steepest accepted ground slope [rad] (about 20 degrees)."""


def _check_finite(name: str, value: float, *, positive: bool = False, nonneg: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and not value > 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    if nonneg and not value >= 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")


@dataclass(frozen=True)
class LinkParams:
    """One uniform rod of the chain (paper Table 1).

    Attributes:
        mass_kg: link mass m [kg], > 0.
        length_m: link length l [m], > 0.
        radius_m: link radius r [m], > 0 (enters the inertia only).
        damping_nms_per_rad: viscous damping D [N m s/rad], >= 0, of the joint at this link's
            proximal end in the paper numbering (link 0: the toe pivot).
    """

    mass_kg: float
    length_m: float
    radius_m: float
    damping_nms_per_rad: float

    def __post_init__(self) -> None:
        """Validate every field (finite; positive where physical)."""
        _check_finite("mass_kg", self.mass_kg, positive=True)
        _check_finite("length_m", self.length_m, positive=True)
        _check_finite("radius_m", self.radius_m, positive=True)
        _check_finite("damping_nms_per_rad", self.damping_nms_per_rad, nonneg=True)

    @property
    def inertia_com_kgm2(self) -> float:
        """Solid cylinder about a transverse axis through the COM: m (3 r^2 + l^2) / 12 [kg m^2]."""
        m, r, length = self.mass_kg, self.radius_m, self.length_m
        return m * (3.0 * r**2 + length**2) / 12.0


_FOOT = LinkParams(mass_kg=0.5, length_m=0.5, radius_m=0.5, damping_nms_per_rad=10.0)
_LEG = LinkParams(mass_kg=1.0, length_m=1.5, radius_m=0.16, damping_nms_per_rad=10.0)
PAPER_LINKS: tuple[LinkParams, ...] = (_FOOT, _LEG, _LEG, _LEG, _LEG, _FOOT)
"""Paper Table 1 / section 4: m, l, r, D for links 0, 1, 2, 3, 4, E."""

DEFAULT_FRICTION_RATIO = 0.5
"""Sliding friction ratio K = f_t / f_n (chosen; the paper gives no value: docs/conventions.md)."""


@dataclass(frozen=True)
class ChainModel:
    """The serial chain in one numbering, rooted at the stance toe.

    Attributes:
        links: the six links in chain order (stance foot first).
        joint_damping_nms_per_rad: (6,) damping of joint i (joint 0 = toe pivot) [N m s/rad].
        gravity_mps2: gravitational acceleration [m/s^2].
        friction_ratio: K, sliding friction over normal force [-].
        heel_toe_split_m: L of paper eq. 18-19 [m] (the stance foot's length by default).
        slope_rad: the ground's slope [rad] (> 0: rising forward). The chain lives in the
            ground's frame (y along the ground, z normal to it), where gravity is turned by
            the slope: (-g sin(slope), -g cos(slope)).
    """

    links: tuple[LinkParams, ...]
    joint_damping_nms_per_rad: tuple[float, ...]
    gravity_mps2: float
    friction_ratio: float
    heel_toe_split_m: float
    slope_rad: float = 0.0

    @functools.cached_property
    def packed(self) -> np.ndarray:
        """(6, 6) read-only array for the compiled core, one row per link.

        Columns: mass [kg], COM inertia [kg m^2], COM offset from the link's joint along the
        link [m], next joint's offset along the link [m], angle offset phi_i - phi_{i-1} - q_i
        [rad], damping of joint i [N m s/rad].
        """
        a = np.zeros((N_LINKS, N_COLS))
        foot0 = self.links[0]
        angle = (0.0, HALF_PI_RAD, 0.0, PI_RAD, 0.0, HALF_PI_RAD)
        for i, link in enumerate(self.links):
            a[i, COL_MASS] = link.mass_kg
            a[i, COL_INERTIA] = link.inertia_com_kgm2
            a[i, COL_COM] = 0.5 * link.length_m
            a[i, COL_NEXT] = link.length_m
            a[i, COL_ANGLE] = angle[i]
            a[i, COL_DAMPING] = self.joint_damping_nms_per_rad[i]
        # Stance foot: rooted at its toe, pointing heel -> toe, so the ankle is *behind* the root.
        a[0, COL_COM] = -0.5 * foot0.length_m
        a[0, COL_NEXT] = -0.5 * foot0.length_m
        # Swing foot: the ankle (joint 5) is the foot's midpoint and centre of mass.
        a[5, COL_COM] = 0.0
        a[5, COL_NEXT] = 0.0
        a.flags.writeable = False
        return a

    @functools.cached_property
    def packed_scalars(self) -> np.ndarray:
        """(8,) read-only array of the chain's scalars for the compiled core.

        g normal to the ground, K, L split, stance-heel offset, swing heel/toe offsets, m0, g
        along the ground (backward on an upward slope).
        """
        foot0, foot5 = self.links[0], self.links[5]
        s = np.array(
            [
                self.gravity_mps2 * math.cos(self.slope_rad),
                self.friction_ratio,
                self.heel_toe_split_m,
                -foot0.length_m,  # stance heel, measured from the toe (joint 0)
                -0.5 * foot5.length_m,  # swing heel, measured from the ankle (joint 5)
                0.5 * foot5.length_m,  # swing toe
                foot0.mass_kg,
                self.gravity_mps2 * math.sin(self.slope_rad),
            ]
        )
        s.flags.writeable = False
        return s


@dataclass(frozen=True)
class BipedParams:
    """The physical biped (paper Table 1), every value overridable and validated.

    ``links`` is in the paper's numbering with leg A standing: (foot A, shank A, thigh A,
    thigh B, shank B, foot B). Use :func:`dataclasses.replace` to override values, e.g.
    ``dataclasses.replace(paper_biped(), friction_ratio=0.8)``.

    Attributes:
        links: six :class:`LinkParams` (paper Table 1).
        gravity_mps2: g [m/s^2], > 0 (paper: 9.8).
        friction_ratio: K = f_t / f_n for sliding point contacts [-], >= 0 (not in the paper).
        heel_toe_split_m: L in paper eq. 18-19 [m]; ``None`` means the stance foot's length.
        slope_rad: the ground's constant slope [rad], > 0 rising forward, |slope| <=
            :data:`MAX_SLOPE_RAD` (paper: 0, flat). The contact stays the paper's plane z = 0
            of the ground's frame; gravity turns by the slope in that frame.
    """

    links: tuple[LinkParams, ...] = PAPER_LINKS
    gravity_mps2: float = G_MPS2
    friction_ratio: float = DEFAULT_FRICTION_RATIO
    heel_toe_split_m: float | None = None
    slope_rad: float = 0.0
    _chains: tuple[ChainModel, ChainModel] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Validate the fields and build the two chain numberings."""
        if not isinstance(self.links, tuple) or len(self.links) != N_LINKS:
            raise ValueError(f"links must be a tuple of {N_LINKS} LinkParams, got {self.links!r}")
        for i, link in enumerate(self.links):
            if not isinstance(link, LinkParams):
                raise ValueError(f"links[{i}] must be a LinkParams, got {type(link).__name__}")
        _check_finite("gravity_mps2", self.gravity_mps2, positive=True)
        _check_finite("friction_ratio", self.friction_ratio, nonneg=True)
        if self.heel_toe_split_m is not None:
            _check_finite("heel_toe_split_m", self.heel_toe_split_m, positive=True)
        _check_finite("slope_rad", self.slope_rad)
        if abs(self.slope_rad) > MAX_SLOPE_RAD:
            raise ValueError(
                f"slope_rad must be in [-{MAX_SLOPE_RAD}, {MAX_SLOPE_RAD}] [rad], "
                f"got {self.slope_rad!r}"
            )
        object.__setattr__(self, "_chains", (self._chain(0), self._chain(1)))

    def _chain(self, stance_side: int) -> ChainModel:
        links = self.links if stance_side == 0 else tuple(reversed(self.links))
        d = [link.damping_nms_per_rad for link in self.links]
        # Each physical joint keeps its damping: joint j of the reversed chain is the paper's
        # joint 6 - j; both feet's toe pivots use the paper's D_0.
        damping = tuple(d) if stance_side == 0 else (d[0], d[5], d[4], d[3], d[2], d[1])
        split = self.heel_toe_split_m if self.heel_toe_split_m is not None else links[0].length_m
        return ChainModel(
            links, damping, self.gravity_mps2, self.friction_ratio, split, float(self.slope_rad)
        )

    def chain(self, stance_side: int) -> ChainModel:
        """The chain rooted at the toe of leg ``stance_side`` (0 = leg A, paper numbering)."""
        if stance_side not in (0, 1):
            raise ValueError(f"stance_side must be 0 or 1, got {stance_side!r}")
        return self._chains[stance_side]

    @functools.cached_property
    def packed(self) -> tuple[np.ndarray, np.ndarray]:
        """((2, 6, 6), (2, 8)) read-only arrays of both numberings for the compiled core."""
        chains = np.stack([c.packed for c in self._chains])
        scalars = np.stack([c.packed_scalars for c in self._chains])
        chains.flags.writeable = False
        scalars.flags.writeable = False
        return chains, scalars

    @property
    def total_mass_kg(self) -> float:
        """Sum of the link masses [kg]."""
        return sum(link.mass_kg for link in self.links)


def paper_biped(**overrides: object) -> BipedParams:
    """The paper's robot (Table 1), with optional field overrides (validated)."""
    return dataclasses.replace(BipedParams(), **overrides)


def chain_for(params: BipedParams, stance_side: int) -> ChainModel:
    """The chain for the current numbering (paper eq. 25-29 renumbering = ``stance_side`` flip)."""
    return params.chain(stance_side)
