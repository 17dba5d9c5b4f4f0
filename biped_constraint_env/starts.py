"""Episode starts: the rest and mid-stride start distributions and reset-state validation."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .advance import nb_start_batch
from .hybrid import wrap_angles
from .kinematics import point_jacobian
from .model import COL_ANGLE, N_LINKS, SC_TOE5, BipedParams
from .modes import Mode
from .simulator import SimArrays, SimOptions, SimState, keypoints
from .validation import check_array, check_choice, check_int, check_mapping, check_real

NOMINAL_POSTURE_RAD = (0.0, -0.1, 0.1, -0.3, -0.4, 0.7)
"""Nominal model-1 posture q (theta0, q1..q5) [rad]: stance leg upright, swing leg back and
bent, swing foot flat 0.41 m above the ground; at rest both ends of the stance foot push."""
MIDSTRIDE_RATE_RANGE_RAD_S = (-1.1, -0.9)
"""Range of the stance foot's turning rate about the toe at a mid-stride start [rad/s]."""
MIDSTRIDE_THETA0_RANGE_RAD = (-0.25, -0.15)
"""Range of the stance foot's heel-up angle theta0 at a mid-stride start [rad]."""
STRIDE_SWING_RANGE_RAD = (-0.3, 0.4)
"""Range of the swing thigh's direction at a stride start [rad from straight down, + forward]:
from the mid-stride start's (0.3 rad behind) to in front of the hip, ready to strike."""
STRIDE_KNEE_RANGE_RAD = (-0.6, -0.05)
"""Range of the swing knee's angle q4 at a stride start [rad] (bent as the mid-stride start's,
to nearly straight)."""
STRIDE_SWING_RATE_RANGE_RAD_S = (0.0, 2.0)
"""Range of the swing thigh's forward turning rate at a stride start [rad/s]."""
STRIDE_FLAT_LEAN_RANGE_RAD = (-0.3, 0.3)
"""Range of the stance leg's forward lean at a stride start on the flat foot (model 1) [rad]."""
STRIDE_FLAT_RATE_RANGE_RAD_S = (-0.6, -0.2)
"""Range of the stance leg's turning rate about the ankle at a stride start on the flat foot
(model 1) [rad/s] (< 0: forward; the hip 0.6-1.8 m/s)."""
STAND_HIP_Y_RANGE_M = (-0.75, -0.45)
"""Range of the hip's position at a standing start, from the front toe [m] (behind it: over
the front heel, between the feet)."""
STAND_HIP_Z_RANGE_M = (2.65, 2.8)
"""Range of the hip's height at a standing start [m] (knees bent; 2.95 m walking)."""
STAND_TOE_Y_RANGE_M = (-1.15, -0.85)
"""Range of the rear toe's position at a standing start, from the front toe [m]."""
STAND_HEEL_UP_RANGE_RAD = (0.05, 0.2)
"""Range of the rear foot's heel-up angle at a standing start [rad]."""
STRIDE_STAND_HIP_Y_RANGE_M = (-0.85, -0.55)
"""Range of the hip's position at a stride-stand start, from the front toe [m]: where a walk's
double support begins, the hip over or behind the rear toe (a walk told to stop enters it at
0.65-0.78 m behind the front toe)."""
STRIDE_STAND_HIP_Z_RANGE_M = (2.8, 2.92)
"""Range of the hip's height at a stride-stand start [m] (2.84-2.91 m in a walk's double
support)."""
STRIDE_STAND_TOE_Y_RANGE_M = (-0.8, -0.5)
"""Range of the rear toe's position at a stride-stand start, from the front toe [m] (a slow
walk's step: about 0.6 m)."""
STRIDE_STAND_HEEL_UP_RANGE_RAD = (0.05, 0.4)
"""Range of the rear foot's heel-up angle at a stride-stand start [rad]."""
STRIDE_BRAKE_HIP_VZ_RANGE_M_S = (-0.5, 0.0)
"""Range of the hip's upward speed at a stride-brake start [m/s]: a walk enters double support
with the hip coming down (0.26-0.54 m/s after a walk told to stop)."""
STRIDE_BRAKE_HEEL_RATE_RANGE_RAD_S = (0.0, 3.0)
"""Range of the rear heel's rising rate at a stride-brake start [rad/s]: the rear foot turning
about its toe as a walk enters double support (1-1.8 rad/s there, then up to 5)."""
BRAKE_HIP_SPEED_RANGE_M_S = (0.0, 0.8)
"""Range of the hip's forward speed at a braking start [m/s]: the standing start moving, from
at rest to a little faster than the command walkers walk on at a zero command (0.4-0.8 m/s)."""
STRIDE_DRIFT_HIP_SPEED_RANGE_M_S = (-0.3, 0.1)
"""Range of the hip's forward speed at a stride-drift start [m/s]: a stop after a slow walk
(0.3-0.8 m/s) comes to rest in double support, then drifts backward, faster and faster (the
command walkers fall back from it 2-6 s after the stop)."""
NUDGE_RATE_RANGE_RAD_S = (-0.6, 0.2)
"""Range of the stance leg's turning rate about the ankle at a nudge start [rad/s] (< 0:
forward): from the flat-foot stride start's fastest to a slow turn backward, so that the rest
start's zero lies inside the range (a policy trained on forward rates alone walks from any of
them and still falls backward from rest: docs/recipes/ppo_gait_rest_50hz.md)."""
RESET_NOISE_SCALE_RAD = 0.01
"""Default half-width of the uniform noise added to q1..q5 at reset [rad]."""
MAX_RESET_NOISE_RAD = 1.0
"""Largest accepted ``reset_noise_scale`` [rad]."""
MAX_START_DRAWS = 100
"""Draws a reset makes for a start above the ground before it gives up (large noise)."""
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
    rate: float = -1.0,
    theta0: float = -0.2,
    lean: float = 0.1,
    swing: float = -0.3,
    knee: float = -0.6,
    swing_rate: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) of a model-2 state in mid-stride, leg A on its toe, turning at ``rate`` [rad/s].

    The stance heel is up by -theta0 [rad] (theta0 <= 0), the stance leg leans forward by
    ``lean`` [rad] with its knee bent 0.05 rad, the swing leg is behind (thigh 0.3 rad back,
    knee bent 0.6 rad, foot level), and the whole body turns forward about the stance toe at
    ``rate`` (< 0: forward) with the swing thigh keeping its direction.

    ``swing``, ``knee`` and ``swing_rate`` place the swing leg elsewhere on its swing (a stride
    start): the swing thigh's direction [rad from straight down, + forward], the knee angle q4
    [rad] and the thigh's forward turning rate [rad/s], the swing foot kept level.
    """
    values = (rate, theta0, lean, swing, knee, swing_rate)
    if not math.isfinite(sum(values)) or theta0 > 0:  # a NaN or inf makes the sum one
        raise ValueError(f"need finite values and theta0 <= 0, got {values}")
    return _midstride_state(*values)


def _midstride_state(rate, theta0, lean, swing, knee, swing_rate):
    """:func:`midstride_start` of checked values (the drawn starts' route, every reset)."""
    q1 = -lean - theta0
    q2 = 0.05
    q3 = swing - (theta0 + q1 + q2)
    q = np.array([theta0, q1, q2, q3, knee, -(swing + knee)])
    return q, np.array([rate, 0.0, 0.0, swing_rate - rate, 0.0, -swing_rate])


def flat_foot_stride_start(
    rate: float, lean: float, swing: float, knee: float, swing_rate: float
) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) of a model-1 state in mid-stride, on the flat stance foot.

    The stance leg leans forward by ``lean`` [rad] (knee bent 0.05 rad) and turns about the
    ankle at ``rate`` [rad/s] (< 0: forward); the swing leg as in :func:`midstride_start`
    (``swing``, ``knee``, ``swing_rate``).
    """
    q, qd = midstride_start(rate, 0.0, lean, swing, knee, swing_rate)
    qd[0], qd[1] = 0.0, rate  # the foot stays flat; the leg turns about the ankle
    return q, qd


def sample_start(
    rng: np.random.Generator,
    start: str | tuple,
    posture: np.ndarray,
    noise_scale: float,
    params: BipedParams,
) -> tuple[np.ndarray, np.ndarray, int]:
    """(q, qd, mode) of a sampled episode start (``start`` in :func:`start_names`, or a mixture).

    A mixture, ((component, weight), ...) with the weights summing to 1: one uniform draw
    first picks the first component whose cumulative weight exceeds it ("mixed" is
    (("rest", 0.5), ("midstride", 0.5))), then that component draws as below.

    "rest": ``posture`` at rest in model 1; "midstride": :func:`midstride_start` with the rate
    and theta0 drawn uniformly from :data:`MIDSTRIDE_RATE_RANGE_RAD_S` and
    :data:`MIDSTRIDE_THETA0_RANGE_RAD`, in model 2; "mixed": one of the two, with probability
    1/2 each (one more uniform draw first); "stride": with probability 1/2 (one more draw
    first) the mid-stride start with the swing leg drawn uniformly along its swing
    (:data:`STRIDE_SWING_RANGE_RAD`, :data:`STRIDE_KNEE_RANGE_RAD`,
    :data:`STRIDE_SWING_RATE_RANGE_RAD_S`; three more draws), else its model-1 counterpart
    (:func:`flat_foot_stride_start`: the lean and rate drawn from
    :data:`STRIDE_FLAT_LEAN_RANGE_RAD` and :data:`STRIDE_FLAT_RATE_RANGE_RAD_S` in place of the
    rate and theta0, then the swing leg's three). All add uniform noise in
    [-noise_scale, noise_scale] to q1..q5 [rad], but "stand" (:func:`stand_start`: its
    rear toe on the ground exactly; four draws place the hip and the rear foot).
    """
    if start == "mixed":
        start = "rest" if rng.random() < 0.5 else "midstride"
    elif not isinstance(start, str):
        start = _pick(start, rng.random())
    q, qd, mode = START_COMPONENTS[start](rng, posture, params)
    if start not in EXACT_STARTS:
        q[1:] += _uniform(rng, -noise_scale, noise_scale, N_LINKS - 1)
    return q, qd, mode


def _rest(rng, posture, params):
    """The ``posture`` at rest in model 1."""
    return np.array(posture, dtype=np.float64), np.zeros(N_LINKS), _FOOT_FLAT


def _midstride(rng, posture, params):
    """:func:`midstride_start` with its rate and theta0 drawn, in model 2."""
    rate = _uniform(rng, *MIDSTRIDE_RATE_RANGE_RAD_S)
    theta0 = _uniform(rng, *MIDSTRIDE_THETA0_RANGE_RAD)
    q, qd = _midstride_state(rate, theta0, *_MIDSTRIDE_SWING)
    return q, qd, _TOE_PIVOT


def _stride(rng, posture, params):
    """The swing leg drawn along its swing: in model 2, or half the draws on the flat foot."""
    flat = rng.random() < 0.5
    if flat:
        rate = _uniform(rng, *STRIDE_FLAT_RATE_RANGE_RAD_S)
        lean = _uniform(rng, *STRIDE_FLAT_LEAN_RANGE_RAD)
    else:
        rate = _uniform(rng, *MIDSTRIDE_RATE_RANGE_RAD_S)
        theta0 = _uniform(rng, *MIDSTRIDE_THETA0_RANGE_RAD)
    swing = _uniform(rng, *STRIDE_SWING_RANGE_RAD)
    knee = _uniform(rng, *STRIDE_KNEE_RANGE_RAD)
    swing_rate = _uniform(rng, *STRIDE_SWING_RATE_RANGE_RAD_S)
    if flat:
        q, qd = flat_foot_stride_start(rate, lean, swing, knee, swing_rate)
        return q, qd, _FOOT_FLAT
    q, qd = _midstride_state(rate, theta0, _MIDSTRIDE_SWING[0], swing, knee, swing_rate)
    return q, qd, _TOE_PIVOT


_FOOT_FLAT, _TOE_PIVOT, _DOUBLE_SUPPORT = (
    int(Mode.FOOT_FLAT),
    int(Mode.TOE_PIVOT),
    int(Mode.DOUBLE_SUPPORT),
)
_MIDSTRIDE_SWING = (0.1, -0.3, -0.6, 0.0)  # midstride_start's lean, swing, knee, swing_rate


def _knee(a: np.ndarray, b: np.ndarray, l1: float, l2: float) -> np.ndarray:
    """The knee of a two-link leg from ``a`` to ``b`` (links l1, l2 [m]), bent forward (+y)."""
    d = b - a
    dist = math.hypot(d[0], d[1])
    x = (l1 * l1 - l2 * l2 + dist * dist) / (2.0 * dist)
    u = d / dist
    n = np.array([-u[1], u[0]]) if u[1] <= 0.0 else np.array([u[1], -u[0]])
    return a + x * u + math.sqrt(max(l1 * l1 - x * x, 0.0)) * n


def stand_start(
    params: BipedParams, hip_y: float, hip_z: float, toe_y: float, heel_up: float
) -> np.ndarray:
    """The joint angles of a model-4 stance: both feet down, the hip at (hip_y, hip_z) [m].

    The front (stance) foot flat with its toe at y = 0, the rear foot on its toe at ``toe_y``
    [m] (< 0), its heel up by ``heel_up`` [rad]; each leg's knee found from its hip and ankle
    (two links), bent forward. Model 4 holds the rear toe on the ground: exact, not perturbed.
    """
    chain = params.chain(0)
    length = [link.length_m for link in chain.links]
    ankle = np.array([-0.5 * length[0], 0.0])
    hip = np.array([hip_y, hip_z])
    rear = np.array([toe_y - 0.5 * length[5] * math.cos(heel_up),
                     0.5 * length[5] * math.sin(heel_up)])  # fmt: skip
    k1, k2 = _knee(ankle, hip, length[1], length[2]), _knee(hip, rear, length[3], length[4])
    phi = [0.0, *(math.atan2(v[1], v[0]) for v in (k1 - ankle, hip - k1, k2 - hip, rear - k2)),
           -heel_up]  # fmt: skip
    rel = np.diff(np.concatenate([[0.0], phi])) - chain.packed[:, COL_ANGLE]
    return wrap_angles(rel)


def stand_rates(
    params: BipedParams, q: np.ndarray, hip_vy: float, hip_vz: float = 0.0, heel_rate: float = 0.0
) -> np.ndarray:
    """The joint rates qd (6,) [rad/s] of model-4 stance ``q``, its hip moving at (hip_vy, hip_vz).

    Model 4's constraints hold exactly to round-off: the front foot stays flat (qd[0] = 0) and
    the rear toe still; the rear foot turns about its toe with its heel rising at ``heel_rate``
    [rad/s] (0 by default: it keeps its heel-up angle), which leaves the hip's velocity
    (hip_vy [m/s] forward, hip_vz up; 0 by default) to fix the other rates: one linear solve.
    """
    chain = params.chain(0)
    rows = np.zeros((N_LINKS, N_LINKS))
    rhs = np.zeros(N_LINKS)
    rows[0, 0] = 1.0  # the front foot flat
    rows[1:3] = point_jacobian(chain, q, 5, float(chain.packed_scalars[SC_TOE5]))  # rear toe
    rows[3:5] = point_jacobian(chain, q, 3, 0.0)  # the hip (link 3's origin)
    rhs[3], rhs[4] = hip_vy, hip_vz
    rows[5] = 1.0  # the rear foot's absolute rate: the sum of the relative rates
    rhs[5] = -heel_rate  # the heel rising turns the foot backward
    qd = np.linalg.solve(rows, rhs)
    qd[0] = 0.0
    return qd


STAND_RANGES = (STAND_HIP_Y_RANGE_M, STAND_HIP_Z_RANGE_M, STAND_TOE_Y_RANGE_M,
                STAND_HEEL_UP_RANGE_RAD)  # fmt: skip
STRIDE_STAND_RANGES = (STRIDE_STAND_HIP_Y_RANGE_M, STRIDE_STAND_HIP_Z_RANGE_M,
                       STRIDE_STAND_TOE_Y_RANGE_M, STRIDE_STAND_HEEL_UP_RANGE_RAD)  # fmt: skip


def _stand_posture(rng, params, ranges=STAND_RANGES):
    """:func:`stand_start` with its hip (y, z), rear toe and heel-up drawn from ``ranges``."""
    return stand_start(params, *(_uniform(rng, *r) for r in ranges))


def _stand(rng, posture, params, ranges=STAND_RANGES):
    """:func:`stand_start` with its hip and rear foot drawn, at rest in model 4."""
    return _stand_posture(rng, params, ranges), np.zeros(N_LINKS), _DOUBLE_SUPPORT


def _brake(rng, posture, params):
    """The standing start's draw moving, its hip forward (:func:`stand_rates`).

    The speed uniform in :data:`BRAKE_HIP_SPEED_RANGE_M_S`: the states a walk stops from.
    """
    q = _stand_posture(rng, params)
    return q, stand_rates(params, q, _uniform(rng, *BRAKE_HIP_SPEED_RANGE_M_S)), _DOUBLE_SUPPORT


def _stride_stand(rng, posture, params):
    """:func:`_stand` in a walk's double-support geometry (:data:`STRIDE_STAND_RANGES`)."""
    return _stand(rng, posture, params, STRIDE_STAND_RANGES)


def _stride_brake(rng, posture, params):
    """:func:`_stride_stand`'s posture moving as a walk enters double support.

    The hip forward (:data:`BRAKE_HIP_SPEED_RANGE_M_S`) and down
    (:data:`STRIDE_BRAKE_HIP_VZ_RANGE_M_S`), the rear heel rising
    (:data:`STRIDE_BRAKE_HEEL_RATE_RANGE_RAD_S`), each uniform (:func:`stand_rates`).
    """
    q = _stand_posture(rng, params, STRIDE_STAND_RANGES)
    ranges = (BRAKE_HIP_SPEED_RANGE_M_S, STRIDE_BRAKE_HIP_VZ_RANGE_M_S,
              STRIDE_BRAKE_HEEL_RATE_RANGE_RAD_S)  # fmt: skip
    return q, stand_rates(params, q, *(_uniform(rng, *r) for r in ranges)), _DOUBLE_SUPPORT


def _stride_drift(rng, posture, params):
    """:func:`_stride_stand`'s posture drifting, mostly backward, as a slow walk's stop does.

    The hip moving level at a speed uniform in :data:`STRIDE_DRIFT_HIP_SPEED_RANGE_M_S`, the
    rear foot keeping its angle (:func:`stand_rates`).
    """
    q = _stand_posture(rng, params, STRIDE_STAND_RANGES)
    return (
        q,
        stand_rates(params, q, _uniform(rng, *STRIDE_DRIFT_HIP_SPEED_RANGE_M_S)),
        _DOUBLE_SUPPORT,
    )


def _nudge(rng, posture, params):
    """The ``posture`` in model 1, the stance leg turning about the ankle.

    Its rate drawn uniformly from :data:`NUDGE_RATE_RANGE_RAD_S` (mostly forward, some
    backward; 0: the rest start), the swing thigh keeping its direction: the states around the
    rest start and between it and walking.
    """
    rate = _uniform(rng, *NUDGE_RATE_RANGE_RAD_S)
    qd = np.zeros(N_LINKS)
    qd[1], qd[3] = rate, -rate
    return np.array(posture, dtype=np.float64), qd, _FOOT_FLAT


START_COMPONENTS = {"rest": _rest, "midstride": _midstride, "stride": _stride, "stand": _stand,
                    "nudge": _nudge, "brake": _brake, "stride_stand": _stride_stand,
                    "stride_brake": _stride_brake, "stride_drift": _stride_drift}  # fmt: skip
"""The start components by name: each draws (q, qd, mode) from a row's generator, the rest
posture and the robot, before the reset noise. A new start is one entry here (``start`` or a
mixture ``start={"stride": 0.75, "midstride": 0.25}`` names it)."""
EXACT_STARTS = frozenset({"stand", "brake", "stride_stand", "stride_brake", "stride_drift"})
"""Components whose state meets a contact constraint exactly: no reset noise (their draws vary
them)."""


REFERENCE_START = "reference"
"""The start component at a state of the reference walk, drawn uniformly with its clock
(reference-state initialisation): the part that holds the walk draws it
(:meth:`~.tracking.Tracking.draw_starts`); its weight in a mixture is the fraction of such
starts. It draws first, one uniform draw per start; the other components then draw as a
start of their own (:func:`split_reference`)."""


def start_names() -> tuple[str, ...]:
    """Named values of the env's ``start``: the components, "mixed" and "reference"."""
    return (*START_COMPONENTS, "mixed", REFERENCE_START)


def split_reference(start: str | tuple) -> tuple[float, str | tuple | None]:
    """(the reference component's weight, the other starts) of a checked ``start``.

    The other components keep their order, renormalised; one left is its name, none None. A
    start without the reference is (0.0, ``start``).
    """
    if start == REFERENCE_START:
        return 1.0, None
    if isinstance(start, str) or REFERENCE_START not in dict(start):
        return 0.0, start
    weight = dict(start)[REFERENCE_START]
    own = [(name, w) for name, w in start if name != REFERENCE_START]
    if len(own) <= 1:
        return weight, own[0][0] if own else None
    total = sum(w for _, w in own)
    return weight, tuple((name, w / total) for name, w in own)


def _pick(mixture: tuple, u: float) -> str:
    """The component of ``mixture`` ((name, weight), ...) that the uniform draw ``u`` picks."""
    total = 0.0
    for name, weight in mixture:
        total += weight
        if u < total:
            return name
    return next(name for name, weight in reversed(mixture) if weight > 0)  # round-off at 1


def draw_starts(
    params: BipedParams,
    options: SimOptions,
    sim: SimArrays,
    idx: np.ndarray,
    rngs: list[np.random.Generator],
    start: str,
    posture: np.ndarray,
    noise_scale: float,
) -> None:
    """Sample and start slots ``idx``, slot ``idx[k]`` drawing from ``rngs[k]``.

    Each slot's (q, qd, mode) comes from :func:`sample_start`; leg A stands, its toe at y = 0.
    A draw that puts a point below the ground (large ``noise_scale``) is drawn again from the
    same generator, up to :data:`MAX_START_DRAWS` times, so that a batched env's automatic
    reset never fails a whole batch step and the single env draws the same starts. Raises
    ValueError, naming ``reset_noise_scale``, if a slot finds no valid start.
    """
    idx = np.asarray(idx, np.int64)
    rows = idx.tolist()
    todo = list(range(len(rows)))
    modes = np.empty(len(rows), np.int64)
    q, qd = sim.q, sim.qd
    chs, scs = params.packed
    iopt, fopt = options.packed[:2]
    for _ in range(MAX_START_DRAWS):
        if len(rows) == 1:  # the single env, a batch's lone reset: the same draws, shorter
            q[rows[0]], qd[rows[0]], modes[0] = sample_start(rngs[0], start, posture,
                                                             noise_scale, params)  # fmt: skip
            low = nb_start_batch(chs, scs, q, qd, sim.ist, sim.fst, sim.forces, sim.status,
                                 sim.n_events, idx, modes, iopt, fopt).tolist()  # fmt: skip
            if low[0] >= -POSITION_TOLERANCE_M:
                return
            continue
        for k in todo:
            i = rows[k]
            q[i], qd[i], modes[k] = sample_start(rngs[k], start, posture, noise_scale, params)
        some = idx if len(todo) == len(rows) else idx[todo]
        low = nb_start_batch(chs, scs, q, qd, sim.ist, sim.fst, sim.forces, sim.status,
                             sim.n_events, some, modes if some is idx else modes[todo], iopt,
                             fopt).tolist()  # fmt: skip
        todo = [k for k, z in zip(todo, low, strict=True) if z < -POSITION_TOLERANCE_M]
        if not todo:
            return
    raise ValueError(
        f"no start above the ground in {MAX_START_DRAWS} draws (lowest z {min(low):.3g} m): "
        f"reset_noise_scale={noise_scale!r} is too large for the {start!r} start"
    )


def start_slots(
    params: BipedParams,
    options: SimOptions,
    sim: SimArrays,
    idx: np.ndarray,
    modes: np.ndarray | None = None,
) -> np.ndarray:
    """Start slots ``idx`` (q, qd set) in ``modes``; returns each one's lowest point z [m].

    For searches that score a start below the ground instead of refusing it.
    """
    idx = np.asarray(idx, np.int64)
    if modes is None:
        mode_of = np.full(idx.shape[0], int(Mode.FOOT_FLAT), np.int64)
    else:
        mode_of = np.asarray(modes, np.int64)
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


RESET_OPTION_KEYS = ("q", "qd", "mode", "stance_side", "root_y")
"""Keys of ``reset(options=...)``."""
MAX_RESET_RATE_RAD_S = 1e3
"""Largest joint rate accepted in ``reset(options=...)`` [rad/s] (the observation's bound)."""
MAX_RESET_ANGLE_RAD = 100.0
"""Largest joint angle accepted in ``reset(options=...)`` or as a posture [rad]."""


def state_from_options(options: Any) -> SimState:
    """A SimState from ``reset(options=...)`` keys q, qd, mode, stance_side, root_y.

    ValueError, naming the key, on an unknown key, a wrong type, shape or range.
    """
    # "command" is taken out before (split_reset_options): named here for the message
    check_mapping("reset option(s)", options, (*RESET_OPTION_KEYS, "command"))
    if "q" not in options:
        raise ValueError("reset options must contain 'q' (theta0, q1..q5) [rad]")
    return SimState(
        t=0.0,
        mode=Mode(check_int("mode", options.get("mode", 1), 1, 4)),
        stance_side=check_int("stance_side", options.get("stance_side", 0), 0, 1),
        q=check_array("q", options["q"], (N_LINKS,), MAX_RESET_ANGLE_RAD, " [rad]"),
        qd=check_array(
            "qd",
            options.get("qd", np.zeros(N_LINKS)),
            (N_LINKS,),
            MAX_RESET_RATE_RAD_S,
            " [rad/s]",
        ),  # fmt: skip
        root_y=check_real("root_y", options.get("root_y", 0.0), -1e6, 1e6, unit=" [m]"),
    )


def check_start_state(params: BipedParams, state: SimState) -> None:
    """ValueError unless ``state`` is inside its model (points above ground, contacts held).

    The message names the reset options at fault (q, qd, mode).
    """
    pts = keypoints(params, state)
    low = {k: round(float(v[1]), 6) for k, v in pts.items() if v[1] < -POSITION_TOLERANCE_M}
    if low:
        raise ValueError(f"q puts points below the ground (z [m]): {low}")
    mode = state.mode
    if mode in (Mode.FOOT_FLAT, Mode.DOUBLE_SUPPORT) and (state.q[0] != 0 or state.qd[0] != 0):
        raise ValueError(
            f"mode {int(mode)} holds the stance foot flat: q[0] (theta0) and qd[0] must be 0"
        )
    if mode in (Mode.TOE_PIVOT, Mode.TOE_HEEL) and state.q[0] > 0:
        raise ValueError(f"mode {int(mode)} pivots on the stance toe: q[0] (theta0) must be <= 0")
    for m, name in ((Mode.TOE_HEEL, "swing_heel"), (Mode.DOUBLE_SUPPORT, "swing_toe")):
        if mode == m and abs(pts[name][1]) > 1e-6:
            raise ValueError(
                f"mode {int(m)} holds the {name} at z = 0, but q puts it at {pts[name][1]:.3g} m"
            )


def check_start_kind(start: Any) -> str | tuple[tuple[str, float], ...]:
    """A named start (:func:`start_names`), or a mixture {component: weight} as ((name, w), ...).

    The weights (>= 0, finite, summing to > 0) are normalised to sum to 1, in the given order.
    """
    if isinstance(start, str):
        return check_choice("start", start, start_names())
    if not isinstance(start, dict):
        raise ValueError(
            f"start must be one of {start_names()} or a mixture {{component: weight}} of "
            f"{(*START_COMPONENTS, REFERENCE_START)}, got {start!r}"
        )
    components = (*START_COMPONENTS, REFERENCE_START)
    check_mapping("start mixture", start, components)
    if not start:
        raise ValueError(f"a start mixture names at least one of {components}")
    weights = {k: check_real(f"start weight of {k!r}", w, 0.0, 1e6) for k, w in start.items()}
    total = sum(weights.values())
    if total <= 0:
        raise ValueError(f"a start mixture needs a positive weight, got {dict(start)!r}")
    return tuple((k, w / total) for k, w in weights.items())


def start_name(start: str | tuple) -> str | dict[str, float]:
    """A start as the ``start`` argument gives it: its name, or the mixture as a dict."""
    return start if isinstance(start, str) else dict(start)


def check_start_settings(
    params: BipedParams, start: Any, posture, reset_noise_scale: float
) -> tuple[str | tuple, np.ndarray, float]:
    """The validated start kind, rest posture (6,) [rad] and noise scale [rad] of an env."""
    if not isinstance(params, BipedParams):
        raise ValueError(f"params must be a BipedParams (e.g. paper_biped()), got {params!r}")
    start = check_start_kind(start)
    noise = check_real(
        "reset_noise_scale", reset_noise_scale, 0.0, MAX_RESET_NOISE_RAD, unit=" [rad]"
    )
    q = check_array("posture", posture, (N_LINKS,), MAX_RESET_ANGLE_RAD, " [rad]")
    try:
        check_start_state(params, SimState(0.0, 1, 0, q, np.zeros(N_LINKS)))
    except ValueError as e:
        raise ValueError(f"posture (a model-1 rest state): {e}") from None
    return start, q, noise
