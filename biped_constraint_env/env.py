"""ConstrainedBiped-v0: a Gymnasium adapter over the four-model hybrid simulator."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numba import njit

from .hybrid import nb_wrap
from .kinematics import NK, nb_hip_kinematics
from .model import N_ACTUATED, N_LINKS, BipedParams, paper_biped
from .modes import EventCode, Mode
from .simulator import (
    DEFAULT_OPTIONS,
    FAST_OPTIONS,
    PAPER_OPTIONS,
    STATUS_NONFINITE,
    STATUS_TERMINATED,
    SimArrays,
    SimOptions,
    SimState,
    advance,
    evaluate,
    keypoints,
    nb_start_batch,
)
from .units import PAPER_SAMPLE_TIME_S

TORQUE_LIMIT_NM = 150.0
"""Default action bound [N m] (>= 120 so that Table 2 fits)."""
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
OBS_RATE_LIMIT_RAD_S = 1e3
"""Bound of the joint-rate observations [rad/s] (values beyond are clipped; with the damping of
10 N m s/rad and 150 N m torques, steady rates stay below ~50 rad/s)."""
OBS_LENGTH_LIMIT_M = 10.0
"""Bound of the hip-position observations [m] (the legs are 3 m long)."""
OBS_SPEED_LIMIT_M_S = 1e3
"""Bound of the hip-velocity observations [m/s]."""
OBS_FORCE_LIMIT_N = 1e5
"""Bound of the contact-force observations [N] (the robot weighs 49 N)."""
OBS_DIM = 24
OBS_NAMES: tuple[str, ...] = (
    "theta0",
    "q1",
    "q2",
    "q3",
    "q4",
    "q5",
    "theta0_dot",
    "q1_dot",
    "q2_dot",
    "q3_dot",
    "q4_dot",
    "q5_dot",
    "hip_y_rel_stance_toe",
    "hip_z",
    "hip_vy",
    "hip_vz",
    "stance_side",
    "mode_1",
    "mode_2",
    "mode_3",
    "mode_4",
    "f_stance_toe",
    "f_stance_heel",
    "f_contact_normal",
)
"""Observation entries, in order (see the env docstring's table)."""
TERMINATION_NON_FINITE = "non_finite"
TERMINATION_FALL = "fall"

PRESETS: dict[str, SimOptions] = {
    "default": DEFAULT_OPTIONS,
    "fast": FAST_OPTIONS,
    "paper": PAPER_OPTIONS,
}
"""Fidelity presets: the accurate defaults (RK4 x 16), the ~6x cheaper "fast" (RK2 x 4, env v0),
and the paper's own numerical choices."""


def _obs_bounds() -> tuple[np.ndarray, np.ndarray]:
    high = np.empty(OBS_DIM)
    high[:6] = np.pi
    high[6:12] = OBS_RATE_LIMIT_RAD_S
    high[12:14] = OBS_LENGTH_LIMIT_M
    high[14:16] = OBS_SPEED_LIMIT_M_S
    high[16:21] = 1.0
    high[21:24] = OBS_FORCE_LIMIT_N
    low = -high
    low[16:21] = 0.0
    return low, high


OBS_LOW, OBS_HIGH = _obs_bounds()


@njit(cache=True)
def nb_observe(chs, scs, Q, QD, IST, FST, FORCES, OBS, HIP, low, high):
    """Fill OBS (n, 24), clipped to [low, high], and HIP (n, 4: hip y, z, vy, vz)."""
    K = np.empty((N_LINKS, NK))
    for i in range(Q.shape[0]):
        side = IST[i, 1]
        mode = IST[i, 0]
        hy, hz, hvy, hvz = nb_hip_kinematics(chs[side], Q[i], QD[i], FST[i, 1], K)
        HIP[i, 0] = hy
        HIP[i, 1] = hz
        HIP[i, 2] = hvy
        HIP[i, 3] = hvz
        for j in range(6):
            OBS[i, j] = nb_wrap(Q[i, j])  # angles, so wrapped to (-pi, pi]
            OBS[i, 6 + j] = QD[i, j]
        OBS[i, 12] = hy - FST[i, 1]
        OBS[i, 13] = hz
        OBS[i, 14] = hvy
        OBS[i, 15] = hvz
        OBS[i, 16] = side
        for m in range(4):
            OBS[i, 17 + m] = 1.0 if mode == m + 1 else 0.0
        OBS[i, 21] = FORCES[i, 0]
        OBS[i, 22] = FORCES[i, 1]
        OBS[i, 23] = FORCES[i, 2]
        for j in range(OBS.shape[1]):
            OBS[i, j] = min(max(OBS[i, j], low[j]), high[j])


def observation_space() -> spaces.Box:
    """The observation Box (bounds in the env docstring's table)."""
    return spaces.Box(OBS_LOW.copy(), OBS_HIGH.copy(), dtype=np.float64)


def resolve_options(preset: str, dt: float, overrides: dict[str, Any]) -> SimOptions:
    """The simulator options of a preset with per-option overrides (None = keep)."""
    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {sorted(PRESETS)}, got {preset!r}")
    if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite number > 0 [s], got {dt!r}")
    changes = {k: v for k, v in overrides.items() if v is not None}
    return PRESETS[preset].replace(**changes)


def validate_actions(actions: Any, limit: float, out_of_range: str) -> np.ndarray:
    """(..., 5) float64 torques [N m]; ValueError on NaN/inf/shape/dtype/range (as documented)."""
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
            raise ValueError(f"action {a} exceeds the torque limit +-{limit} N m")
        a = np.clip(a, -limit, limit)
    return a


def validate_action(action: Any, limit: float, out_of_range: str) -> np.ndarray:
    """(5,) float64 torques [N m] from one action (see :func:`validate_actions`)."""
    a = action if isinstance(action, np.ndarray) else np.asarray(action)
    if a.shape != (N_ACTUATED,):
        raise ValueError(f"action must have shape ({N_ACTUATED},), got {a.shape}")
    return validate_actions(a, limit, out_of_range)


def sample_initial_q(
    rng: np.random.Generator, posture: np.ndarray, noise_scale: float
) -> np.ndarray:
    """The nominal posture with uniform noise in [-scale, scale] on q1..q5 [rad]."""
    q = np.array(posture, dtype=np.float64)
    q[1:] += rng.uniform(-noise_scale, noise_scale, size=N_LINKS - 1)
    return q


def midstride_start(
    rate: float = -1.0, theta0: float = -0.2, lean: float = 0.1
) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) of a model-2 state in mid-stride, leg A on its toe, turning at ``rate`` [rad/s].

    The stance heel is up by -theta0 [rad] (theta0 <= 0), the stance leg leans forward by
    ``lean`` [rad] with its knee bent 0.05 rad, the swing leg is behind (thigh 0.3 rad back,
    knee bent 0.6 rad, foot level), and the whole body turns forward about the stance toe at
    ``rate`` (< 0: forward) with the swing thigh keeping its direction.
    """
    if not (np.isfinite(rate) and np.isfinite(theta0) and np.isfinite(lean)) or theta0 > 0:
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
    rate = rng.uniform(*MIDSTRIDE_RATE_RANGE_RAD_S)
    theta0 = rng.uniform(*MIDSTRIDE_THETA0_RANGE_RAD)
    q, qd = midstride_start(rate, theta0)
    q[1:] += rng.uniform(-noise_scale, noise_scale, size=N_LINKS - 1)
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
    if np.any(low < -POSITION_TOLERANCE_M):
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
    sim.ist[idx] = 0
    sim.ist[idx, 0] = int(Mode.FOOT_FLAT) if modes is None else modes
    sim.fst[idx] = 0.0
    chs, scs = params.packed
    iopt, fopt, _, _ = options.packed
    low = nb_start_batch(
        chs,
        scs,
        sim.q,
        sim.qd,
        sim.ist,
        sim.fst,
        sim.forces,
        sim.status,
        sim.n_events,
        np.asarray(idx, np.int64),
        iopt,
        fopt,
    )
    return low


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


REWARD_TERMS = ("reward_forward", "reward_alive", "reward_switch", "reward_step", "reward_ctrl")
"""Names of the reward terms in ``info`` (their sum is the reward)."""


def fallen(hip_z, threshold_m: float | None):
    """Whether the hip is below ``threshold_m`` [m] (never when the threshold is None)."""
    if threshold_m is None:
        return hip_z < -np.inf
    return hip_z < threshold_m


def cycle_position(mode: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """4 * steps + (mode - 1): increases by one at every forward model switch."""
    return 4 * steps + (mode - 1)


def reward_terms(
    progress_m,
    dt: float,
    switches,
    steps,
    alive,
    tau: np.ndarray,
    limit: float,
    w_forward: float,
    w_alive: float,
    w_switch: float,
    w_step: float,
    w_ctrl: float,
) -> tuple:
    """The reward terms of one control period, in REWARD_TERMS order (see Rewards).

    Works elementwise on one env (scalars, ``tau`` (5,)) or on n envs (arrays (n,), ``tau``
    (n, 5)) with the same floating-point operations, so both environments agree bit for bit.

    Args:
        progress_m: hip progress [m]. dt: control period [s]. switches: forward model switches
            in the period. steps: walking steps completed in the period. alive: whether the
            period did not end in a termination. tau: applied torques [N m]. limit: torque
            bound [N m]. w_*: the weights.
    """
    if tau.ndim == 1:  # one env: plain floats; sequential sum, as numpy's for 5 elements
        tau_sq = sum(x * x for x in tau.tolist())
    else:
        tau_sq = np.sum(tau * tau, axis=-1)
    return (
        w_forward * progress_m / dt,
        w_alive * alive,
        w_switch * switches,
        w_step * steps,
        -w_ctrl * tau_sq / (limit * limit),
    )


class ConstrainedBipedEnv(gym.Env):
    r"""Planar six-link biped whose ground contact is a constraint (Maeba et al. 2013).

    ## Description
    The robot of the paper "Bipedal Locomotion Model Based on Constraint Condition by
    Newton-Euler Method": a serial chain of six rods (stance foot, shank, thigh, thigh, shank,
    swing foot; 5 kg in all) in the vertical y-z plane, rooted at the stance toe. Its motion
    switches among the paper's four models (1: stance foot flat; 2: stance toe pivot; 3: toe
    + swing heel; 4: new stance foot flat + old toe), each with its own unknowns, solved by
    the Newton-Euler method with the contacts as constraints (README, Model). One walking step
    is the cycle 1 -> 2 -> 3 -> 4 -> 1; the legs swap roles at 3 -> 4. The agent applies the
    five joint torques and should walk forward (+y) as far as it can without leaving the four
    models. Conventions (angles, signs) are those of MODEL.md and the README.

    ## Action Space
    ``Box(-torque_limit_nm, torque_limit_nm, (5,), float32)``, torques in N m, held over
    the control period ``dt``, in the *current* numbering (index 0 acts at the stance ankle).
    With ``stop_at_switch=True`` a period ends early, just after a model switch (its impact
    and, at 3 -> 4, the renumbering applied), so that the next action acts from the switch
    itself: the paper changes the torque at the switch, and a torque held past the 3 -> 4
    renumbering would otherwise act on other joints. ``info["t"]`` gives the time.

    | Num | joint | acts on (link i vs i-1)        | limit [N m] | sign |
    |-----|-------|--------------------------------|-------------|------|
    | 0   | 1     | stance shank vs stance foot    | 150         | + counter-clockwise on link i |
    | 1   | 2     | stance thigh vs stance shank   | 150         | same |
    | 2   | 3     | swing thigh vs stance thigh    | 150         | same |
    | 3   | 4     | swing shank vs swing thigh     | 150         | same |
    | 4   | 5     | swing foot vs swing shank      | 150         | same |

    Out-of-range torques are clipped (``out_of_range="clip"``, default) or refused with a
    ``ValueError`` (``"raise"``). NaN, inf, a wrong shape or a non-numeric dtype raise
    ``ValueError``.

    ## Observation Space
    ``Box(shape=(24,), float64)``:

    | Num | quantity | min | max | unit |
    |-----|----------|-----|-----|------|
    | 0-5 | theta0, q1..q5 (MODEL.md coordinates, current numbering), wrapped | -pi | pi | rad |
    | 6-11 | their rates | -1e3 | 1e3 | rad/s |
    | 12 | hip y relative to the stance toe | -10 | 10 | m |
    | 13 | hip height z | -10 | 10 | m |
    | 14-15 | hip velocity (y, z) | -1e3 | 1e3 | m/s |
    | 16 | stance leg (0 = leg A, 1 = leg B) | 0 | 1 | - |
    | 17-20 | model one-hot (paper models 1, 2, 3, 4) | 0 | 1 | - |
    | 21 | stance toe vertical force (F_R in models 1, 4) | -1e5 | 1e5 | N |
    | 22 | stance heel vertical force (F_L in models 1, 4; 0 in 2, 3) | -1e5 | 1e5 | N |
    | 23 | point-contact normal force f_n (models 3, 4; else 0) | -1e5 | 1e5 | N |

    The bounds are the named constants ``OBS_RATE_LIMIT_RAD_S``, ``OBS_LENGTH_LIMIT_M``,
    ``OBS_SPEED_LIMIT_M_S`` and ``OBS_FORCE_LIMIT_N``; values beyond them (far outside walking)
    are clipped to them. ``OBS_NAMES`` lists the entries; ``info["mode"]`` repeats the model
    number (1-4).

    ## Rewards
    ``reward = reward_forward + reward_alive + reward_switch + reward_step + reward_ctrl``:
    ``reward_forward = forward_reward_weight * (hip_y' - hip_y) / dt`` (hip progress),
    ``reward_alive = alive_bonus`` for a period not ended by an out-of-model event,
    ``reward_switch = switch_bonus * (forward model switches in this period)``,
    ``reward_step = step_bonus * (walking steps completed in this period)`` and
    ``reward_ctrl = -ctrl_cost_weight * sum((tau / torque_limit_nm)^2)``. Defaults 1.0, 0.5,
    1.0, 5.0, 0.1. There is no fall penalty (it makes agents timid); the small alive and switch
    bonuses reward staying inside the models and moving through the cycle, which the forward
    term alone does not (it pays for a lunge). ``info`` contains each term.

    ## Starting State
    Model 1, leg A standing, stance toe at y = 0, at rest, with
    ``q = NOMINAL_POSTURE_RAD = (0, -0.1, 0.1, -0.3, -0.4, 0.7)`` rad plus uniform noise in
    ``[-reset_noise_scale, reset_noise_scale]`` (default 0.01 rad) on q1..q5.
    With ``start="midstride"`` (v2): model 2, leg A on its toe, turning forward about it:
    :func:`midstride_start` with the rate uniform in ``MIDSTRIDE_RATE_RANGE_RAD_S`` (-1.1 to
    -0.9 rad/s), the heel-up angle theta0 uniform in ``MIDSTRIDE_THETA0_RANGE_RAD`` (-0.25 to
    -0.15 rad), and the same noise on q1..q5.
    ``reset(options={"q": ..., "qd": ..., "mode": ..., "stance_side": ..., "root_y": ...})``
    starts from any state in MODEL.md's coordinates (validated: points on or above the
    ground, model constraints satisfied; a ``ValueError`` says what is wrong).

    ## Episode End
    ### Termination
    Any out-of-model event of the simulator (``info["termination_reason"]`` names it):
    ``stance_foot_tips_back``, ``stance_heel_down``, ``swing_toe_strike``,
    ``swing_foot_touchdown``, ``body_below_ground``, ``swing_heel_pulls``,
    ``stance_toe_pulls``, ``stance_foot_pulls`` (force events end the episode only with
    ``strict=True``), ``step_behind_stance_toe``, ``zeno``, ``non_finite`` (the
    numerical state blew up; the observation is the last finite state), and, only if
    ``fall_hip_height_m`` is set, ``fall`` (the hip below that height [m] at the end of a
    period; off by default). A fall is one of
    these (a knee or the hip below the ground).
    ### Truncation
    By the time limit only: ``max_episode_steps=1000`` control periods at registration.

    ## Arguments
    | Parameter | Type | Default | Description (unit) | affects |
    |-----------|------|---------|--------------------|---------|
    | params | BipedParams | paper_biped() | the robot | dynamics |
    | preset | str | "default" | "default" (RK4 x 16), "fast" (RK2 x 4) or "paper" | dynamics |
    | dt | float | 0.02 | control period [s] | dynamics, reward |
    | integrator, substeps, impact, locate_events, jdot, strict, | | None | override | dynamics |
    | heel_force_includes_foot_weight | | | one option of the preset (``SimOptions``) | |
    | stop_at_switch | bool | None (off) | end a period at a model switch (event-driven) | dyn. |
    | torque_limit_nm | float | 150 | action bound [N m] | action |
    | out_of_range | str | "clip" | "clip" or "raise" | action |
    | forward_reward_weight | float | 1.0 | per (m/s) of hip progress | reward |
    | alive_bonus | float | 0.5 | per control period inside the models | reward |
    | switch_bonus | float | 1.0 | per forward model switch | reward |
    | step_bonus | float | 5.0 | per completed walking step | reward |
    | ctrl_cost_weight | float | 0.1 | per unit of sum((tau/limit)^2) | reward |
    | reset_noise_scale | float | 0.01 | uniform noise on q1..q5 [rad] | start |
    | fall_hip_height_m | float or None | None | end the episode when the hip is below [m] | end |
    | posture | array (6,) | NOMINAL_POSTURE_RAD | nominal start posture [rad] ("rest") | start |
    | start | str | "rest" | "rest" (model 1 at rest) or "midstride" (model 2, moving) | start |
    | render_mode | str | None | "rgb_array" or "human" | render |

    ## Version History
    * v2: the walking task. ``dt=0.005``, ``stop_at_switch=True`` (the torque changes at each
      model switch, as in the paper), ``start="midstride"``, 6000 periods (30 s). Why: from
      v1's start at rest the centre of mass lies over the stance heel with the swing leg behind
      (no ankle torque can push it forward), and torques held through a switch act on other
      joints after the renumbering; README, "Learning to walk further".
    * v1: default integrator RK4 x 16 substeps per 20 ms, chosen by the accuracy study
      (``preset="default"``).
    * v0: initial release; RK2 x 4 substeps per 20 ms (registered with ``preset="fast"``).

    Example:
        >>> import gymnasium as gym
        >>> import biped_constraint_env
        >>> env = gym.make("ConstrainedBiped-v1")
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, info["mode"]
        ((24,), 1)
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 50}

    def __init__(
        self,
        params: BipedParams | None = None,
        preset: str = "default",
        dt: float = PAPER_SAMPLE_TIME_S,
        integrator: str | None = None,
        substeps: int | None = None,
        impact: str | None = None,
        locate_events: bool | None = None,
        jdot: str | None = None,
        strict: bool | None = None,
        heel_force_includes_foot_weight: bool | None = None,
        stop_at_switch: bool | None = None,
        torque_limit_nm: float = TORQUE_LIMIT_NM,
        out_of_range: str = "clip",
        forward_reward_weight: float = 1.0,
        alive_bonus: float = 0.5,
        switch_bonus: float = 1.0,
        step_bonus: float = 5.0,
        ctrl_cost_weight: float = 0.1,
        reset_noise_scale: float = RESET_NOISE_SCALE_RAD,
        fall_hip_height_m: float | None = None,
        posture=NOMINAL_POSTURE_RAD,
        start: str = "rest",
        render_mode: str | None = None,
    ):
        """Create the environment (see the class docstring, Arguments)."""
        self.params = params if params is not None else paper_biped()
        self.dt = float(dt)
        self.options = resolve_options(
            preset,
            dt,
            dict(
                integrator=integrator,
                substeps=substeps,
                impact=impact,
                locate_events=locate_events,
                jdot=jdot,
                strict=strict,
                heel_force_includes_foot_weight=heel_force_includes_foot_weight,
                stop_at_switch=stop_at_switch,
            ),
        )
        if not (np.isfinite(torque_limit_nm) and torque_limit_nm > 0):
            raise ValueError(f"torque_limit_nm must be finite and > 0, got {torque_limit_nm!r}")
        if out_of_range not in ("clip", "raise"):
            raise ValueError(f"out_of_range must be 'clip' or 'raise', got {out_of_range!r}")
        for name, v in (
            ("forward_reward_weight", forward_reward_weight),
            ("step_bonus", step_bonus),
            ("ctrl_cost_weight", ctrl_cost_weight),
            ("reset_noise_scale", reset_noise_scale),
        ):
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self.posture = np.asarray(posture, dtype=np.float64)
        if self.posture.shape != (N_LINKS,):
            raise ValueError(f"posture must have shape ({N_LINKS},), got {self.posture.shape}")
        check_start_state(self.params, SimState(0.0, 1, 0, self.posture, np.zeros(N_LINKS)))
        self.torque_limit_nm = float(torque_limit_nm)
        self.out_of_range = out_of_range
        self.weights = (
            float(forward_reward_weight),
            float(alive_bonus),
            float(switch_bonus),
            float(step_bonus),
            float(ctrl_cost_weight),
        )
        self.reset_noise_scale = float(reset_noise_scale)
        if start not in STARTS:
            raise ValueError(f"start must be one of {STARTS}, got {start!r}")
        self.start = start
        if fall_hip_height_m is not None and not (
            isinstance(fall_hip_height_m, (int, float)) and np.isfinite(fall_hip_height_m)
        ):
            raise ValueError(
                f"fall_hip_height_m must be a finite number or None, got {fall_hip_height_m!r}"
            )
        self.fall_hip_height_m = None if fall_hip_height_m is None else float(fall_hip_height_m)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.dt))}
        self.action_space = spaces.Box(
            -self.torque_limit_nm, self.torque_limit_nm, (N_ACTUATED,), np.float32
        )
        self.observation_space = observation_space()
        self._sim = SimArrays(1)
        self._obs = np.zeros((1, OBS_DIM))
        self._hip = np.zeros((1, 4))
        self._tau_table = np.zeros((1, 4, N_ACTUATED))
        self._renderer = None

    # ---------------------------------------------------------------- state access
    @property
    def state(self) -> SimState:
        """The simulator state (immutable snapshot)."""
        return self._sim.get(0)

    def keypoints(self) -> dict[str, np.ndarray]:
        """World positions [m] of toes, heels, ankles, knees and hip of both legs, by name."""
        return keypoints(self.params, self.state)

    # ---------------------------------------------------------------- Gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode (see the class docstring, Starting State)."""
        super().reset(seed=seed)
        if options:
            state = state_from_options(options)
            check_start_state(self.params, state)
            forces = evaluate(self.params, state, np.zeros(N_ACTUATED), self.options)[1]
            self._sim.set(0, state, forces)
        else:
            q, qd, mode = sample_start(
                self.np_random, self.start, self.posture, self.reset_noise_scale
            )
            self._sim.q[0], self._sim.qd[0] = q, qd
            start_sampled(self.params, self.options, self._sim, np.zeros(1, np.int64), mode)
        self._observe()
        info = self._info(events=(), terms=dict.fromkeys(REWARD_TERMS, 0.0), reason=None)
        if self.render_mode == "human":
            self.render()
        return self._obs[0].copy(), info

    def step(self, action):
        """Apply the torques for one control period (see the class docstring)."""
        tau = validate_action(action, self.torque_limit_nm, self.out_of_range)
        sim = self._sim
        if sim.status[0] != 0:
            raise RuntimeError("step() called after the episode ended; call reset()")
        mode0, _, steps0, _ = sim.ist[0].tolist()
        hip_y0 = self._hip[0, 0].item()
        self._tau_table[0] = tau
        advance(self.params, sim, self._tau_table, self.dt, self.options)
        self._observe()
        status = sim.status[0].item()
        events = sim.events_of(0) if sim.n_events[0] else ()
        reason = None
        if status == STATUS_TERMINATED:
            reason = next(e.code.name.lower() for e in events if e.terminal)
        elif status == STATUS_NONFINITE:
            reason = TERMINATION_NON_FINITE
        elif fallen(self._hip[0, 1].item(), self.fall_hip_height_m):
            reason = TERMINATION_FALL
        mode1, _, steps1, _ = sim.ist[0].tolist()
        parts = reward_terms(
            self._hip[0, 0].item() - hip_y0,
            self.dt,
            cycle_position(mode1, steps1) - cycle_position(mode0, steps0),
            steps1 - steps0,
            reason is None,
            tau,
            self.torque_limit_nm,
            *self.weights,
        )
        terms = dict(zip(REWARD_TERMS, parts, strict=True))
        reward = sum(parts)
        info = self._info(events, terms, reason)
        if self.render_mode == "human":
            self.render()
        return self._obs[0].copy(), reward, reason is not None, False, info

    def _observe(self) -> None:
        chs, scs = self.params.packed
        s = self._sim
        nb_observe(
            chs, scs, s.q, s.qd, s.ist, s.fst, s.forces, self._obs, self._hip, OBS_LOW, OBS_HIGH
        )

    def _info(self, events, terms, reason) -> dict[str, Any]:
        mode, side, steps, _ = self._sim.ist[0].tolist()
        return {
            "mode": mode,
            "stance_side": side,
            "steps_completed": steps,
            "t": self._sim.fst[0, 0].item(),
            "hip_y": self._hip[0, 0].item(),
            "switches": tuple(
                (e.t, e.mode_from, e.mode_to) for e in events if e.code == EventCode.MODE_SWITCH
            ),
            "events": tuple((e.t, e.code.name.lower(), e.terminal) for e in events),
            "termination_reason": reason,
            **terms,
        }

    def render(self):
        """An RGB frame (``rgb_array``) or a window (``human``) of the stick figure."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode")
            return None
        from .render import Renderer

        if self._renderer is None:
            self._renderer = Renderer()
        st = self.state
        frame = self._renderer.frame(
            self.keypoints(), int(st.mode), st.t, st.stance_side, st.steps_completed
        )
        if self.render_mode == "human":
            self._renderer.show(frame, 1.0 / self.metadata["render_fps"])
            return None
        return frame

    def close(self):
        """Close the render window, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
