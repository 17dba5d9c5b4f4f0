"""Named physical constants (SI units only).

Every number the physics uses that is not a model parameter lives here, with its unit in the
name and its source in the comment.
"""

from __future__ import annotations

import math

G_MPS2 = 9.8
"""Gravitational acceleration [m/s^2] (paper, section 4)."""

PAPER_SAMPLE_TIME_S = 0.020
"""The paper's sampling time [s] (paper, section 4)."""

HALF_PI_RAD = 0.5 * math.pi
"""Angle offset between a foot (heel -> toe) and its shank [rad] (docs/conventions.md)."""

PI_RAD = math.pi
"""Angle offset between the stance thigh (knee -> hip) and the swing thigh (hip -> knee) [rad]."""
