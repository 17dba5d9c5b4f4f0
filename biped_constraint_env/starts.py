"""Episode starts: the rest and mid-stride start distributions and reset-state validation."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .model import N_LINKS, BipedParams
from .modes import Mode
from .simulator import SimArrays, SimOptions, SimState, keypoints, nb_start_batch

NOMINAL_POSTURE_RAD = (0.0, -0.1, 0.1, -0.3, -0.4, 0.7)
"""Nominal model-1 posture q (theta0, q1..q5) [rad]: stance leg upright, swing leg back and
bent, swing foot flat 0.41 m above the ground; at rest both ends of the stance foot push."""
MIDSTRIDE_RATE_RANGE_RAD_S = (-1.1, -0.9)
"""Range of the stance foot's turning rate about the toe at a mid-stride start [rad/s]."""
MIDSTRIDE_THETA0_RANGE_RAD = (-0.25, -0.15)
"""Range of the stance foot's heel-up angle theta0 at a mid-stride start [rad]."""
STARTS = ("rest", "midstride")
"""Values of the env's ``start`` argument."""
RESET_NOISE_SCALE_RAD = 0.01
"""Default half-width of the uniform noise added to q1..q5 at reset [rad]."""
POSITION_TOLERANCE_M = 1e-9
"""Penetration accepted when validating a reset state [m]."""


def sample_initial_q(
    rng: np.random.Generator, posture: np.ndarray, noise_scale: float
) -> np.ndarray:
    """The nominal posture with uniform noise in [-scale, scale] on q1..q5 [rad]."""
    q = np.array(posture, dtype=np.float64)
    q[1:] += _uniform(rng, -noise_scale, noise_scale, N_LINKS - 1)
    return q


def _uniform(rng: np.random.Generator, low: float, high: float, size: int | None = None):
    """``rng.uniform(low, high, size)``: the same numbers, from a cheaper call.

    numpy computes ``low + (high - low) * rng.random()``; its argument handling costs
    several us per call, which a reset pays three times.
    """
    return low + (high - low) * rng.random(size)


def midstride_start(
    rate: float = -1.0, theta0: float = -0.2, lean: float = 0.1
) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) of a model-2 state in mid-stride, leg A on its toe, turning at ``rate`` [rad/s].

    The stance heel is up by -theta0 [rad] (theta0 <= 0), the stance leg leans forward by
    ``lean`` [rad] with its knee bent 0.05 rad, the swing leg is behind (thigh 0.3 rad back,
    knee bent 0.6 rad, foot level), and the whole body turns forward about the stance toe at
    ``rate`` (< 0: forward) with the swing thigh keeping its direction.
    """
    if not (math.isfinite(rate) and math.isfinite(theta0) and math.isfinite(lean)) or theta0 > 0:
        raise ValueError(f"need finite rate, lean and theta0 <= 0, got {rate}, {theta0}, {lean}")
    q1 = -lean - theta0
    q2, sw, q4 = 0.05, -0.3, -0.6
    q3 = sw - (theta0 + q1 + q2)
    q = np.array([theta0, q1, q2, q3, q4, -(sw + q4)])
    return q, np.array([rate, 0.0, 0.0, -rate, 0.0, 0.0])


def sample_start(
    rng: np.random.Generator, start: str, posture: np.ndarray, noise_scale: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """(q, qd, mode) of a sampled episode start (``start`` in :data:`STARTS`).

    "rest": ``posture`` at rest in model 1; "midstride": :func:`midstride_start` with the rate
    and theta0 drawn uniformly from :data:`MIDSTRIDE_RATE_RANGE_RAD_S` and
    :data:`MIDSTRIDE_THETA0_RANGE_RAD`, in model 2. Both add uniform noise in
    [-noise_scale, noise_scale] to q1..q5 [rad].
    """
    if start == "rest":
        return sample_initial_q(rng, posture, noise_scale), np.zeros(N_LINKS), int(Mode.FOOT_FLAT)
    rate = _uniform(rng, *MIDSTRIDE_RATE_RANGE_RAD_S)
    theta0 = _uniform(rng, *MIDSTRIDE_THETA0_RANGE_RAD)
    q, qd = midstride_start(rate, theta0)
    q[1:] += _uniform(rng, -noise_scale, noise_scale, N_LINKS - 1)
    return q, qd, int(Mode.TOE_PIVOT)


def start_sampled(
    params: BipedParams,
    options: SimOptions,
    sim: SimArrays,
    idx: np.ndarray,
    modes: np.ndarray | None = None,
) -> None:
    """Start slots ``idx`` (q and qd already sampled) in ``modes`` (default: model 1).

    Leg A stands, its toe at y = 0. Raises ValueError if a sampled posture puts a point below
    the ground.
    """
    low = start_slots(params, options, sim, idx, modes)
    if low.min() < -POSITION_TOLERANCE_M:
        raise ValueError(
            f"a sampled start posture is below the ground (lowest z {low.min():.3g} m); "
            "reduce reset_noise_scale or change the posture"
        )


def start_slots(
    params: BipedParams,
    options: SimOptions,
    sim: SimArrays,
    idx: np.ndarray,
    modes: np.ndarray | None = None,
) -> np.ndarray:
    """Start slots ``idx`` as :func:`start_sampled` does; returns each one's lowest point z [m].

    For searches that score a start below the ground instead of refusing it.
    """
    idx = np.asarray(idx, np.int64)
    mode_of = np.empty(idx.shape[0], np.int64)
    mode_of[:] = int(Mode.FOOT_FLAT) if modes is None else modes
    chs, scs = params.packed
    iopt, fopt, _, _ = options.packed
    return nb_start_batch(
        chs,
        scs,
        sim.q,
        sim.qd,
        sim.ist,
        sim.fst,
        sim.forces,
        sim.status,
        sim.n_events,
        idx,
        mode_of,
        iopt,
        fopt,
    )


def state_from_options(options: dict[str, Any]) -> SimState:
    """A SimState from ``reset(options=...)`` keys q, qd, mode, stance_side, root_y."""
    unknown = set(options) - {"q", "qd", "mode", "stance_side", "root_y"}
    if unknown:
        raise ValueError(f"unknown reset option(s) {sorted(unknown)}")
    if "q" not in options:
        raise ValueError("reset options must contain 'q' (theta0, q1..q5) [rad]")
    mode = options.get("mode", 1)
    if mode not in (1, 2, 3, 4):
        raise ValueError(f"mode must be one of 1, 2, 3, 4, got {mode!r}")
    return SimState(
        t=0.0,
        mode=Mode(int(mode)),
        stance_side=int(options.get("stance_side", 0)),
        q=np.asarray(options["q"], dtype=np.float64),
        qd=np.asarray(options.get("qd", np.zeros(N_LINKS)), dtype=np.float64),
        root_y=float(options.get("root_y", 0.0)),
    )


def check_start_state(params: BipedParams, state: SimState) -> None:
    """ValueError unless ``state`` is inside its model (points above ground, contacts held)."""
    pts = keypoints(params, state)
    low = {k: v[1] for k, v in pts.items() if v[1] < -POSITION_TOLERANCE_M}
    if low:
        raise ValueError(f"reset state puts points below the ground (z [m]): {low}")
    mode = state.mode
    if mode in (Mode.FOOT_FLAT, Mode.DOUBLE_SUPPORT) and (state.q[0] != 0 or state.qd[0] != 0):
        raise ValueError(
            f"model {int(mode)} holds the stance foot flat: theta0 and its rate must be 0"
        )
    if mode in (Mode.TOE_PIVOT, Mode.TOE_HEEL) and state.q[0] > 0:
        raise ValueError("models 2-3 pivot on the stance toe: theta0 must be <= 0 (heel up)")
    for m, name in ((Mode.TOE_HEEL, "swing_heel"), (Mode.DOUBLE_SUPPORT, "swing_toe")):
        if mode == m and abs(pts[name][1]) > 1e-6:
            raise ValueError(
                f"model {int(m)} holds the {name} at z = 0, got z = {pts[name][1]:.3g} m"
            )


def check_start_settings(
    params: BipedParams, start: str, posture, reset_noise_scale: float
) -> tuple[str, np.ndarray, float]:
    """The validated start kind, rest posture (6,) [rad] and noise scale [rad] of an env."""
    if start not in STARTS:
        raise ValueError(f"start must be one of {STARTS}, got {start!r}")
    if not (
        isinstance(reset_noise_scale, (int, float))
        and np.isfinite(reset_noise_scale)
        and reset_noise_scale >= 0
    ):
        raise ValueError(
            f"reset_noise_scale must be a finite number >= 0, got {reset_noise_scale!r}"
        )
    q = np.asarray(posture, dtype=np.float64)
    if q.shape != (N_LINKS,):
        raise ValueError(f"posture must have shape ({N_LINKS},), got {q.shape}")
    check_start_state(params, SimState(0.0, 1, 0, q, np.zeros(N_LINKS)))
    return start, q, float(reset_noise_scale)
