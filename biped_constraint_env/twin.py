"""The soft-contact twin: the same planar six-link biped in MuJoCo, with MuJoCo's contact.

The paper's model holds contact as a constraint (four models, no penetration, no springs);
the twin is what most of the field simulates: a floating planar chain (the base foot A's
ankle, free in y, z and pitch; the five joints as hinges) whose heels and toes touch the
ground through MuJoCo's soft contact (penetration and a spring-damper response set by
``solref``, friction K in a pyramidal cone). Lengths, masses, inertias about the joint axis,
joint damping, gravity and the slope are the project's (:class:`~.model.BipedParams`); the
paper's damping of the stance toe pivot (joint 0, a joint to the ground) acts as a torque from
the ground on the stance foot while its toe touches (the twin has no pivot joint: its feet are
free bodies on the ground).

The twin reports its state in the paper's terms, as a robot's estimator would: the stance leg
and the model (1-4) estimated from which heel and toe touch (a point touches while its normal
force exceeds :data:`CONTACT_ON_N` and stops once it has stayed below :data:`CONTACT_OFF_N` for
:data:`CONTACT_RELEASE_S`: the hysteresis), the joint angles and rates in the current
stance's numbering (theta0 the stance foot's angle, q1..q5 relative angles,
:func:`~.hybrid.nb_renumber`'s convention), the stance toe's position and the points'
normal forces. A completed step is a touchdown: the stance leg's foot flat on the ground (heel
and toe touching), the other foot than the last step's (or the start's); in the constraint
model, the cycle's return from model 4 to model 1. The twin's feet may skip models 3 and 4 (a
soft heel strike can unload the old toe at once) and a contact may chatter, which neither
counts a step nor changes the alternation.

Requires MuJoCo (the ``bench`` extra: ``pip install -e ".[bench]"``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .hybrid import nb_wrap
from .kinematics import nb_forward_pass
from .model import COL_DAMPING, COL_INERTIA, COL_MASS, N_LINKS, BipedParams

CONTACT_ON_N = 1.0
"""A heel or toe touches once its normal force exceeds this [N] (about 2% of the weight)."""
CONTACT_OFF_N = 0.1
"""... and stops touching once its normal force has stayed below this [N] for
:data:`CONTACT_RELEASE_S` (a soft contact chatters: its force drops to 0 for a millisecond
and back while the point stays on the ground)."""
CONTACT_RELEASE_S = 0.005
"""How long a touching point's force must stay below :data:`CONTACT_OFF_N` to release it [s]."""
FALL_HIP_M = 1.5
"""A hip below this height [m] is a fall in the twin, where the env sets none (standing, the
hip is at 2.95 m; a knee at the ground brings it below 1.5 m)."""
POINTS = ("heel_a", "toe_a", "heel_b", "toe_b")
"""The contact points, each a small sphere at a foot's end (index: 2 x leg + (0 heel, 1 toe))."""
OFFSETS = (0.0, math.pi / 2, 0.0, math.pi, 0.0, math.pi / 2)
"""The angle offsets of the chain's joints (``ChainModel.packed``'s ``COL_ANGLE``)."""


@dataclass(frozen=True)
class TwinOptions:
    """The twin's numerical and contact options (``physics={"engine": "mujoco", ...}``).

    Attributes:
        timestep_s: MuJoCo's time step [s] (semi-implicit Euler).
        solref: MuJoCo's contact ``solref`` (time constant [s], damping ratio): the contact's
            spring-damper; MuJoCo advises a time constant of at least two time steps.
        solimp: MuJoCo's contact ``solimp`` (impedance at zero and full penetration, its width
            [m], midpoint, power).
        point_radius_m: the radius of the heel and toe spheres [m]; the ground plane sits this
            far below z = 0, so that a point touches at z = 0 as in the paper.
    """

    timestep_s: float = 0.0005
    solref: tuple[float, float] = (0.002, 1.0)
    solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    point_radius_m: float = 0.005


def twin_mjcf(params: BipedParams, options: TwinOptions = TwinOptions(), weld: bool = False) -> str:
    """The MJCF text of the twin of ``params`` (leg A's numbering, the base at foot A's ankle).

    Each body's local +y axis is its link's direction (u(phi) = (cos phi, sin phi) in y-z), its
    hinge about +x at the body's origin (the link's proximal joint), so that the hinge angles
    are the paper's q1..q5 with leg A standing and the base's pitch is foot A's angle.
    ``weld``: foot A fixed flat to the world, no contact, MuJoCo's RK4 (the constraint
    model's model 1, for validation).
    """
    ch = params.chain(0).packed
    lengths = [link.length_m for link in params.links]
    g = params.gravity_mps2
    gy, gz = -g * math.sin(params.slope_rad), -g * math.cos(params.slope_rad)
    r = options.point_radius_m
    k = params.friction_ratio
    sr, si = options.solref, options.solimp
    contact = (f'friction="{k:.17g} 0.005 0.0001" condim="3" solref="{sr[0]:.17g} {sr[1]:.17g}" '
               f'solimp="{" ".join(f"{x:.17g}" for x in si)}"')  # fmt: skip

    def inertial(i: int, com_y: float) -> str:
        ixx = ch[i, COL_INERTIA]
        return (f'<inertial pos="0 {com_y:.17g} 0" mass="{ch[i, COL_MASS]:.17g}" '
                f'diaginertia="{ixx:.17g} {ixx:.17g} {ixx:.17g}"/>')  # fmt: skip

    def quat(a: float) -> str:
        return f'quat="{math.cos(a / 2):.17g} {math.sin(a / 2):.17g} 0 0"'

    def hinge(i: int) -> str:
        return (f'<joint name="q{i}" type="hinge" axis="1 0 0" '
                f'damping="{ch[i, COL_DAMPING]:.17g}" limited="false"/>')  # fmt: skip

    def points(leg: str, half: float) -> str:
        return "".join(
            f'<geom name="{end}_{leg}" type="sphere" size="{r:.17g}" pos="0 {s * half:.17g} 0" '
            f'mass="0" {contact}/>' for end, s in (("heel", -1.0), ("toe", 1.0)))  # fmt: skip

    # foot B: the ankle at its midpoint, pointing heel -> toe (the paper's link 5)
    body = (f'<body name="foot_b" pos="0 {lengths[4]:.17g} 0" {quat(OFFSETS[5])}>{hinge(5)}'
            f'{inertial(5, 0.0)}{points("b", 0.5 * lengths[5])}</body>')  # fmt: skip
    names = {1: "shank_a", 2: "thigh_a", 3: "thigh_b", 4: "shank_b"}
    for i in (4, 3, 2, 1):
        pos = 0.0 if i == 1 else lengths[i - 1]
        body = (f'<body name="{names[i]}" pos="0 {pos:.17g} 0" {quat(OFFSETS[i])}>{hinge(i)}'
                f'{inertial(i, 0.5 * lengths[i])}{body}</body>')  # fmt: skip
    base = ('<joint name="base_y" type="slide" axis="0 1 0" limited="false"/>'
            '<joint name="base_z" type="slide" axis="0 0 1" limited="false"/>'
            '<joint name="base_pitch" type="hinge" axis="1 0 0" limited="false"/>')  # fmt: skip
    if weld:
        base = ""
    foot_a = (f'<body name="foot_a">{base}{inertial(0, 0.0)}{points("a", 0.5 * lengths[0])}'
              f'{body}</body>')  # fmt: skip
    motors = "".join(f'<motor name="m{i}" joint="q{i}" gear="1"/>' for i in range(1, 6))
    flag = '<flag contact="disable"/>' if weld else ""
    return (
        '<mujoco model="biped_twin">'
        f'<option timestep="{options.timestep_s:.17g}" gravity="0 {gy:.17g} {gz:.17g}" '
        f'integrator="{"RK4" if weld else "Euler"}" cone="pyramidal">'
        f"{flag}</option>"
        "<worldbody>"
        f'<geom name="ground" type="plane" size="0 0 1" pos="0 0 {-r:.17g}" {contact}/>'
        f"{foot_a}</worldbody><actuator>{motors}</actuator></mujoco>"
    )


def absolute_angles(q: np.ndarray, side: int) -> np.ndarray:
    """The six links' absolute directions in the physical order (foot A ... foot B).

    ``q``: the paper's angles with leg ``side`` standing (its numbering); the legs of the
    other numbering point the other way (+pi), the feet heel -> toe (:func:`~.hybrid.nb_renumber`).
    """
    phi = np.cumsum(np.asarray(q, float) + np.asarray(OFFSETS))
    if side == 0:
        return phi
    return np.array([phi[5 - k] + (0.0 if k in (0, 5) else math.pi) for k in range(N_LINKS)])


def numbering(phi: np.ndarray, w: np.ndarray, side: int) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) of the paper with leg ``side`` standing.

    From the physical links' directions ``phi`` and rates ``w`` (foot A ... foot B).
    """
    if side == 1:
        phi = np.array([phi[5 - j] + (0.0 if j in (0, 5) else math.pi) for j in range(N_LINKS)])
        w = w[::-1]
    q = np.empty(N_LINKS)
    qd = np.empty(N_LINKS)
    q[0], qd[0] = nb_wrap(phi[0]), w[0]
    for j in range(1, N_LINKS):
        q[j] = nb_wrap(phi[j] - phi[j - 1] - OFFSETS[j])
        qd[j] = w[j] - w[j - 1]
    return q, qd


class Twin:
    """One MuJoCo twin of ``params``: set and read its state in the paper's terms.

    ``step(tau, duration)``: the paper's five torques of the current numbering [N m], held for
    ``duration`` [s] of MuJoCo steps, the contact estimate updated after each.
    """

    def __init__(self, params: BipedParams, options: TwinOptions = TwinOptions()):
        """Build the MuJoCo model and data."""
        import mujoco

        self.mujoco = mujoco
        self.params, self.options = params, options
        self.model = mujoco.MjModel.from_xml_string(twin_mjcf(params, options))
        self.data = mujoco.MjData(self.model)
        self.geoms = [self.model.geom(n).id for n in POINTS]
        self.feet = (self.model.body("foot_a").id, self.model.body("foot_b").id)
        self.joints = [self.model.body(b).id for b in ("thigh_a", "thigh_b", "shank_b")]
        self.toe_damping = float(params.links[0].damping_nms_per_rad)  # the paper's D0
        self.lengths = [link.length_m for link in params.links]
        self.half = (0.5 * self.lengths[0], 0.5 * self.lengths[5])
        self.touch = np.zeros(4, bool)
        self.forces = np.zeros(4)
        self.low_s = np.zeros(4)  # how long each point's force has been below CONTACT_OFF_N
        self.mode, self.side, self.steps = 1, 0, 0
        self._wrench = np.zeros(6)

    # -------------------------------------------------------------- state
    def set_state(self, q, qd, side: int, root_y: float, mode: int) -> None:
        """Start at the paper's state; the estimate starts there.

        ``q``, ``qd`` in leg ``side``'s numbering, the stance toe at ``root_y``, in ``mode``.
        """
        mj = self.mujoco
        ch = self.params.chain(side).packed
        _, _, _, o, vo, _ = nb_forward_pass(ch, np.asarray(q, float), np.asarray(qd, float),
                                            np.zeros(N_LINKS), float(root_y), 0.0)  # fmt: skip
        phi = absolute_angles(q, side)
        w = np.cumsum(qd) if side == 0 else np.cumsum(qd)[::-1]
        ankle_a, vel_a = (o[1], vo[1]) if side == 0 else (o[5], vo[5])
        qa, qda = numbering(phi, w, 0)
        d = self.data
        mj.mj_resetData(self.model, d)
        d.qpos[:] = [ankle_a[0], ankle_a[1], phi[0], *qa[1:]]
        d.qvel[:] = [vel_a[0], vel_a[1], w[0], *qda[1:]]
        mj.mj_forward(self.model, d)
        self.mode, self.side, self.steps = int(mode), int(side), 0
        self._stepped = int(side)  # the foot the last step (or the start) stood on
        self._read_forces()
        on = self.forces > CONTACT_ON_N
        self.touch = on | self._expected(mode, side)  # a start's contacts as the paper has them
        self.low_s[:] = 0.0

    @staticmethod
    def _expected(mode: int, side: int) -> np.ndarray:
        """The points touching in ``mode`` with leg ``side`` standing (heel, toe per leg)."""
        t = np.zeros(4, bool)
        s, o = 2 * side, 2 * (1 - side)
        t[s + 1] = True  # the stance toe, in every model
        if mode in (1, 4):
            t[s] = True  # the stance heel (model 4: the new stance foot, flat)
        if mode == 3:
            t[o] = True  # the swing heel
        if mode == 4:
            t[o + 1] = True  # the old stance toe
        return t

    def paper_state(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(q, qd, root_y) in the current stance's numbering."""
        d = self.data
        phi = np.cumsum([d.qpos[2], *(d.qpos[3:] + np.asarray(OFFSETS[1:]))])
        w = np.cumsum(d.qvel[2:])
        q, qd = numbering(phi, w, self.side)
        y = d.qpos[0]  # foot A's ankle
        if self.side == 0:
            return q, qd, float(y + self.half[0] * math.cos(phi[0]))
        y += sum(length * math.cos(phi[i]) for i, length in enumerate(self.lengths[1:5], 1))
        return q, qd, float(y + self.half[1] * math.cos(phi[5]))

    def paper_forces(self) -> np.ndarray:
        """(stance toe, stance heel, the point contact's) normal forces [N], as observed.

        The point contact: the swing heel in model 3, the old stance toe in model 4 (the
        chain renumbered, the new stance foot flat); none in models 1 and 2.
        """
        s, o, f = 2 * self.side, 2 * (1 - self.side), self.forces
        point = f[o] if self.mode == 3 else f[o + 1] if self.mode == 4 else 0.0
        return np.array([f[s + 1], f[s], point])

    # -------------------------------------------------------------- stepping
    def _read_forces(self) -> None:
        mj, d = self.mujoco, self.data
        self.forces[:] = 0.0
        for c in range(d.ncon):
            con = d.contact[c]
            for k, gid in enumerate(self.geoms):
                if gid in (con.geom1, con.geom2):
                    mj.mj_contactForce(self.model, d, c, self._wrench)
                    self.forces[k] += abs(self._wrench[0])

    def _estimate(self) -> None:
        """The touching points (hysteresis), and from them the model and the stance leg.

        The swing foot flat: model 4 (renumbered: the new foot stands, the old stance toe is
        the point contact) while the old toe touches, else model 1 of the new foot; the stance
        foot flat: model 1; on its toe alone: model 3 with the swing heel down, else model 2.
        With nothing of the stance foot touching, the other foot's contact makes it the stance
        (its toe alone: model 2; else model 1); in the air, nothing changes.
        """
        f = self.forces
        self.low_s = np.where(f < CONTACT_OFF_N, self.low_s + self.options.timestep_s, 0.0)
        t = self.touch = np.where(self.touch, self.low_s < CONTACT_RELEASE_S, f > CONTACT_ON_N)
        s = self.side
        o = 1 - s
        hs, ts, ho, to = t[2 * s], t[2 * s + 1], t[2 * o], t[2 * o + 1]
        mode, side = self.mode, s
        if self.mode == 4 and hs and ts:
            mode = 4 if to else 1
        elif ho and to:
            mode, side = (4 if ts else 1), o
        elif hs and ts:
            mode = 1
        elif ts:
            mode = 3 if ho else 2
        elif hs:
            mode = 1
        elif ho or to:
            mode, side = (2 if to else 1), o
        if t[2 * side] and t[2 * side + 1] and side != self._stepped:  # a new foot flat
            self.steps += 1
            self._stepped = side
        self.mode, self.side = mode, side

    def step(self, tau_paper: np.ndarray, duration: float) -> None:
        """Hold the paper's torques (current numbering) for ``duration`` [s].

        The paper's damping of the stance toe pivot (joint 0) acts as a torque from the ground
        on the stance foot, ``-D0`` times its angular velocity, while its toe touches.
        """
        mj, d = self.mujoco, self.data
        n = max(1, round(duration / self.options.timestep_s))
        tau = np.asarray(tau_paper, float)
        for _ in range(n):
            d.ctrl[:] = tau if self.side == 0 else -tau[::-1]
            d.xfrc_applied[:] = 0.0
            if self.touch[2 * self.side + 1]:
                w = d.qvel[2] if self.side == 0 else float(np.sum(d.qvel[2:]))
                d.xfrc_applied[self.feet[self.side], 3] = -self.toe_damping * w
            mj.mj_step(self.model, d)
            self._read_forces()
            self._estimate()

    def fallen(self, hip_height_m: float | None = None) -> bool:
        """A fall: the hip below ``hip_height_m`` or a knee at or below the ground.

        ``hip_height_m``: default :data:`FALL_HIP_M`. A knee down is a body other than the
        feet on the ground.
        """
        z = self.data.xpos[self.joints, 2]  # the knees and the hip (joint origins)
        return bool(z[1] < (FALL_HIP_M if hip_height_m is None else hip_height_m) or
                    min(z[0], z[2]) <= 0.0)  # fmt: skip

    @property
    def time(self) -> float:
        """MuJoCo's time [s]."""
        return float(self.data.time)
