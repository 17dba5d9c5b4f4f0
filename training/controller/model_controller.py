"""A model-based walking controller: operational-space torques from the simulator's own model.

Every control period the controller reads the state from the observation (joint angles and
rates, model, stance side), asks the simulator for the affine map from the five torques to the
joint accelerations and contact forces of the current model (six solves of that model), and
chooses the torques by a small least-squares problem with inequality constraints:

* tracking rows (computed torque, PD on the output error) for, per model,
  - model 1 (foot flat): the stance knee; until the hip passes ``hy_lift`` ahead of the stance
    toe the swing leg holds the start posture and the stance ankle loads the heel (centre of
    pressure at the heel, which drives the body forward); after that the swing leg swings and
    the ankle unloads the heel (target ``heel_f``) so that the heel lifts (model 2);
  - model 2 (toe pivot): ankle rate damped (foot and shank turn together about the toe), stance
    knee, swing thigh toward the landing angle ``land`` (+ feedback on hip speed and position),
    swing knee flexed (``flex``) and extended (``knee_land``) as the thigh nears ``land``,
    swing foot toe-up (``foot_up``) so that the heel strikes first;
  - model 3 (toe + heel): rates damped, swing foot rotated down (``kp3``, ``kd3``);
  - model 4 (new foot flat + old toe): stance knee, trailing knee flexed, old toe unloaded
    (target ``toe_lift_f``) so that it lifts (model 1 with the roles swapped);
* inequality constraints, enforced by an active set (a violated one becomes a row of weight
  1e3, so it holds to within about 0.1 N): every contact force that must push stays
  >= ``fmin`` (stance toe, the flat foot's ends, the heel in model 3), the trailing foot's
  toe and heel accelerate away from the ground while it is below ``zc`` and behind the stance
  toe (+ ``clear_y``), and the torque limits.

The contact forces are exact (the simulator's own Newton-Euler solve), so the torques it picks
keep the contacts legal at the sample; between samples the torque is held. With the paper's
20 ms period and torques held through a model switch that is not enough (a torque chosen for
model 3 acts on other joints after the 3 -> 4 renumbering): the controller is meant for the env
with ``stop_at_switch=True`` and a short period (``dt=0.005``). docs/walking.md reports what
it does.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from biped_constraint_env.actions import TORQUE_LIMIT_NM
from biped_constraint_env.clock import at_rest as _at_rest
from biped_constraint_env.hybrid import wrap_angles
from biped_constraint_env.kinematics import nb_kin_point, nb_point_jacobian
from biped_constraint_env.model import SC_HEEL5, SC_TOE5, BipedParams, paper_biped
from biped_constraint_env.modes import Mode
from biped_constraint_env.observation import OBS_NAMES
from biped_constraint_env.simulator import (
    DEFAULT_OPTIONS,
    SimOptions,
    SimState,
    evaluate,
    keypoints,
)
from biped_constraint_env.starts import NOMINAL_POSTURE_RAD, midstride_start

_I = {n: i for i, n in enumerate(OBS_NAMES)}
# outputs y = C q + c over (theta0, q1..q5): stance ankle, stance knee, swing thigh from the
# downward vertical (+ forward), swing knee, swing foot pitch (0 flat, + toe up), stance
# shank from the upward vertical (+ backward)
_C = np.array(
    [
        [0, 1, 0, 0, 0, 0],
        [0, 0, 1, 0, 0, 0],
        [1, 1, 1, 1, 0, 0],
        [0, 0, 0, 0, 1, 0],
        [1, 1, 1, 1, 1, 1],
        [1, 1, 0, 0, 0, 0],
    ],
    dtype=np.float64,
)
_C0 = np.zeros(6)  # the swing foot pitch phi5 is the sum plus 2 pi
START_POSTURE = NOMINAL_POSTURE_RAD[3:]  # q3..q5 held in model 1 before the swing [rad]

DEFAULT_GAINS: dict[str, float] = {
    "kp": 103.5,  # output PD [1/s^2]
    "kd": 18.96,  # [1/s]
    "emax": 0.5338,  # error clip [rad]
    "land": 0.3642,  # swing-thigh landing angle [rad]
    "fb_v": 0.02856,  # landing angle per m/s of hip speed above v_des [rad s/m]
    "v_des": 1.005,  # [m/s]
    "fb_y": -0.01527,  # landing angle per m of hip ahead of the stance toe [rad/m]
    "blend": 0.1615,  # knee extends over this last part of the thigh's swing [rad]
    "flex": 0.7626,  # swing knee flexion [rad]
    "knee_land": 0.02796,  # swing knee flexion at landing [rad]
    "foot_up": 0.2538,  # swing foot pitch, toe up [rad]
    "sk": 0.07281,  # stance knee in models 2 and 3 [rad]
    "sk1": 0.06132,  # stance knee in models 1 and 4 [rad]
    "hy_lift": 0.1133,  # hip ahead of the stance toe at which the heel is unloaded [m]
    "hy_swing": -0.03089,  # hip ahead of the stance toe at which the swing leg swings [m]
    "heel_f": -6.937,  # heel force target when unloading it [N]
    "toe_lift_f": -15.44,  # old-toe force target in model 4 [N]
    "kp3": 30.22,  # swing foot rotation in model 3 [1/s^2]
    "kd3": 5.444,  # [1/s]
    "fmin": 9.216,  # least push of a contact that must push [N]
    "zc": 0.05894,  # clearance of the trailing foot [m]
    "kpz": 100.0,  # clearance PD [1/s^2]
    "kdz": 20.0,  # [1/s]
    "clear_y": 0.1576,  # clearance applies while the swing ankle is behind stance toe + this [m]
    "v1": 2.415,  # model-1 hip-speed target [m/s] for the stance ankle (0: push, heel loaded)
    "kv": 4.931,  # hip-speed feedback gain in model 1 [1/s]
    "lift_dv": 0.02119,  # heel lift delayed by this per m/s of hip speed below v1 [m s/m]
    "w_force": 1.0,  # weight of the force-target rows
    "reg": 0.0001,  # Tikhonov regularisation of the torques
}


def _smooth(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3 - 2 * x)


def state_from_obs(obs: np.ndarray) -> SimState:
    """The simulator state (up to root_y, which the dynamics do not use) from one observation."""
    obs = np.asarray(obs, dtype=np.float64)
    mode = int(np.argmax(obs[_I["mode_1"] : _I["mode_4"] + 1])) + 1
    q = obs[_I["theta0"] : _I["q5"] + 1].copy()
    qd = obs[_I["theta0_dot"] : _I["q5_dot"] + 1].copy()
    if mode in (1, 4):
        q[0] = qd[0] = 0.0
    return SimState(0.0, Mode(mode), int(round(obs[_I["stance_side"]])), q, qd)


def _checked_gains(gains: dict[str, float] | None, what: str) -> dict[str, float]:
    unknown = set(gains or {}) - set(DEFAULT_GAINS)
    if unknown:
        raise ValueError(f"unknown {what} {sorted(unknown)}; known: {sorted(DEFAULT_GAINS)}")
    if not all(np.isfinite(v) for v in (gains or {}).values()):
        raise ValueError(f"{what} must be finite")
    return dict(gains or {})


def at_rest(state: SimState) -> bool:
    """Whether a state is a start at rest (:func:`biped_constraint_env.clock.at_rest`)."""
    return bool(_at_rest(int(state.mode), state.qd))


class ModelController:
    """Torques [N m] (5,) from an observation or a state; see the module docstring.

    With ``start_gains`` the controller has a *start phase*: an observation at rest
    (:func:`at_rest`) starts it, and the first change of the stance leg (the first 4 -> 1
    switch: the first step completed) ends it. In the start phase ``start_gains`` override the
    gait's gains. This is the controller's only memory, so call it on the observations of one
    episode in order (one controller per environment).
    """

    def __init__(
        self,
        gains: dict[str, float] | None = None,
        params: BipedParams | None = None,
        options: SimOptions = DEFAULT_OPTIONS,
        limit: float = TORQUE_LIMIT_NM,
        start_gains: dict[str, float] | None = None,
    ):
        """Gains override :data:`DEFAULT_GAINS`, start gains those (unknown names: ValueError)."""
        self.g = {**DEFAULT_GAINS, **_checked_gains(gains, "gains")}
        self.start_g = (
            None
            if start_gains is None
            else {**self.g, **_checked_gains(start_gains, "start gains")}
        )
        self.params = params if params is not None else paper_biped()
        self.options = options
        self.limit = float(limit)
        self.starting_side: int | None = None  # the stance leg of the start phase (None: off)

    def reset(self) -> None:
        """Forget the start phase (call at every episode start; a rest start arms it again)."""
        self.starting_side = None

    def gains_for(self, state: SimState) -> dict[str, float]:
        """The gains for the next torque: the start phase's or the gait's (updates the phase)."""
        if self.start_g is None:
            return self.g
        if at_rest(state):
            self.starting_side = state.stance_side
        elif self.starting_side is not None and state.stance_side != self.starting_side:
            self.starting_side = None  # the first step is complete
        return self.g if self.starting_side is None else self.start_g

    def __call__(self, obs: np.ndarray, residual: np.ndarray | None = None) -> np.ndarray:
        """Torques for one observation (24,) or a batch (n, 24) -> (5,) or (n, 5).

        ``residual`` [N m] (same leading shape, (5,) or (n, 5)): added to the controller's
        torques and the sum projected back onto its constraints (see :meth:`torques`). A
        controller with a start phase takes one observation at a time (its phase is per
        episode).
        """
        obs = np.asarray(obs, dtype=np.float64)
        if obs.ndim == 2:
            if self.start_g is not None:
                raise ValueError("a controller with a start phase takes one observation at once")
            res = [None] * len(obs) if residual is None else np.asarray(residual, np.float64)
            return np.stack(
                [self.torques(state_from_obs(o), r) for o, r in zip(obs, res, strict=True)]
            )
        state = state_from_obs(obs)
        return self.torques(state, residual, self.gains_for(state))

    # ------------------------------------------------------------------ model queries
    def _affine(self, state: SimState):
        """Qdd = A tau + b (6x5, 6) and forces = F tau + f0 (5x5, 5) of the current model."""
        z = np.zeros(5)
        qdd0, f0, _ = evaluate(self.params, state, z, self.options)
        A, F = np.zeros((6, 5)), np.zeros((5, 5))
        for i in range(5):
            z[i] = 1.0
            qdd, f, _ = evaluate(self.params, state, z, self.options)
            z[i] = 0.0
            A[:, i], F[:, i] = qdd - qdd0, f - f0
        return A, qdd0, F, f0

    def _point(self, state: SimState, name: str, axis: int):
        """Coordinate, exact Jacobian row (6,) and J-dot q-dot of a keypoint along ``axis``.

        ``name`` is "hip", "swing_toe" or "swing_heel"; ``axis`` 0 is y (forward), 1 is z (up);
        the coordinate is relative to the root (the stance toe).
        """
        ch = self.params.chain(state.stance_side)
        link, s = 3, 0.0  # the hip is joint 3, the origin of link 3
        if name != "hip":
            link, s = 5, float(ch.packed_scalars[SC_TOE5 if name == "swing_toe" else SC_HEEL5])
        kin = nb_kin_point(ch.packed, state.q, state.qd, link, s)  # (py, pz, vy, vz, ay, az)
        J = nb_point_jacobian(ch.packed, state.q, link, s)[axis]
        return kin[axis], J, kin[4 + axis]

    # ------------------------------------------------------------------ the law
    # ~100 lines on purpose: the law reads as the paper's phases in order (stance, swing, start
    # phase, constraint projection); split, its shared targets and forces would travel through
    # a dozen arguments.
    def torques(
        self,
        state: SimState,
        residual: np.ndarray | None = None,
        gains: dict[str, float] | None = None,
    ) -> np.ndarray:
        """Torques [N m] (5,) for a simulator state.

        With ``residual`` (5,) [N m] (a learned correction): the torques nearest to the
        controller's plus the residual that still satisfy the inequality constraints (contacts
        pushing by ``fmin``, the trailing foot's clearance, the torque limits) at the sample, a
        safety projection. ``gains``: the gains to use (default: the gait's).
        """
        g = self.g if gains is None else gains
        m = int(state.mode)
        q, qd = state.q, state.qd
        y, yd = wrap_angles(_C @ q + _C0), _C @ qd
        pts = keypoints(self.params, state)
        hy = pts["hip"][0] - pts["stance_toe"][0]
        _, Jhip, ahip0 = self._point(state, "hip", 0)
        vy = Jhip @ qd
        A, b, F, f0 = self._affine(state)
        rows: list[tuple[float, np.ndarray, float]] = []  # weight, row over tau, target

        def track(k, ref, kp=g["kp"], kd=g["kd"]):
            des = kp * np.clip(wrap_angles(ref - y[k]), -g["emax"], g["emax"]) - kd * yd[k]
            rows.append((1.0, _C[k] @ A, des - _C[k] @ b))

        def damp(k):
            track(k, y[k], 0.0, g["kd"])

        def force(i, target):
            rows.append((g["w_force"], F[i] / 10, (target - f0[i]) / 10))

        land = g["land"] + g["fb_v"] * (vy - g["v_des"]) + g["fb_y"] * hy
        s = _smooth((y[2] - land + g["blend"]) / g["blend"])
        knee = -g["flex"] * (1 - s) - g["knee_land"] * s
        slow = max(0.0, g["v1"] - vy) if g["v1"] > 0 else 0.0
        starting = m == 1 and hy < g["hy_lift"] + g["lift_dv"] * slow  # heel still loaded
        if m == 1:
            track(1, g["sk1"])
            if hy < g["hy_swing"]:  # hold the start posture of the swing leg
                for j, ref in zip((3, 4, 5), START_POSTURE, strict=True):
                    rows.append((1.0, A[j], g["kp"] * (ref - q[j]) - g["kd"] * qd[j] - b[j]))
            else:
                track(2, land)
                track(3, knee)
                track(4, g["foot_up"])
            if not starting:  # unload the heel so that it lifts
                force(1, g["heel_f"])
            elif g["v1"] > 0:  # stance ankle: hip speed toward v1 (the foot's ends push)
                ay = g["kv"] * (g["v1"] - vy)
                rows.append((1.0, Jhip @ A, ay - Jhip @ b - ahip0))
            else:  # load the heel (centre of pressure at the heel drives the body forward)
                force(0, g["fmin"] + 1.0)
        elif m == 2:
            damp(0)
            track(1, g["sk"])
            track(2, land)
            track(3, knee)
            track(4, g["foot_up"])
        elif m == 3:
            damp(0)
            track(1, g["sk"])
            damp(2)
            damp(3)
            track(4, -0.3, g["kp3"], g["kd3"])
        else:
            track(1, g["sk1"])
            track(3, -g["flex"])
            rows.append((0.3, _C[5] @ A, -g["kd"] * yd[5] - _C[5] @ b))
            force(2, g["toe_lift_f"])

        ineq: list[tuple[np.ndarray, float, float]] = []  # row @ tau + offset >= bound
        fmin = g["fmin"]
        if m in (1, 2) and pts["swing_ankle"][0] < pts["stance_toe"][0] + g["clear_y"]:
            for name in ("swing_toe", "swing_heel"):
                z, Jz, acc0 = self._point(state, name, 1)
                if z < g["zc"]:
                    bound = g["kpz"] * (g["zc"] - z) - g["kdz"] * (Jz @ qd)
                    ineq.append((Jz @ A, Jz @ b + acc0, bound))
        ineq.append((F[0], f0[0], fmin))  # stance toe (the flat foot's toe in models 1, 4)
        if starting or m == 4:
            ineq.append((F[1], f0[1], fmin))  # flat foot's heel
        if m == 3:
            ineq.append((F[2], f0[2], fmin))  # swing heel
        for i in range(5):
            e = np.zeros(5)
            e[i] = 1.0
            ineq += [(e, 0.0, -self.limit), (-e, 0.0, -self.limit)]
        tau = self._solve(rows, ineq)
        if residual is not None:
            r = np.asarray(residual, dtype=np.float64)
            if r.shape != (5,) or not np.all(np.isfinite(r)):
                raise ValueError(f"residual must be 5 finite torques, got {r!r}")
            target = tau + r
            tau = self._solve([(1.0, e, t) for e, t in zip(np.eye(5), target, strict=True)], ineq)
        return np.clip(tau, -self.limit, self.limit)

    def _solve(self, rows, ineq) -> np.ndarray:
        """Weighted least squares over the rows; violated inequalities join as rows of 1e3."""
        active: list[int] = []
        for _ in range(8):
            rr = rows + [(1e3, ineq[i][0], ineq[i][2] - ineq[i][1]) for i in active]
            w = np.array([r[0] for r in rr])
            R = np.array([r[1] for r in rr])
            t = np.array([r[2] for r in rr])
            tau = np.linalg.solve(
                (R * w[:, None]).T @ R + self.g["reg"] * np.eye(5), (R * w[:, None]).T @ t
            )
            slack = [(c[0] @ tau + c[1] - c[2], i) for i, c in enumerate(ineq) if i not in active]
            worst = min(slack, default=(0.0, -1))
            if worst[0] >= -1e-6:
                break
            active.append(worst[1])
        return tau


CONTROLLERS_DIR = Path(__file__).resolve().parent / "gains"
"""The shipped gain sets (``"model:NAME"`` names ``CONTROLLERS_DIR/NAME.json``)."""
TEACHER = "model:teacher_robust+start_rest"
"""The teacher: the noise-robust gait and its start phase from rest (docs/walking.md)."""


def shipped_controllers() -> list[str]:
    """The names of the shipped gain sets (``"model:NAME"``)."""
    return sorted(p.stem for p in CONTROLLERS_DIR.glob("*.json"))


def controller_from(spec: str, limit: float = TORQUE_LIMIT_NM) -> ModelController:
    """The controller of a config string.

    ``"model"``: DEFAULT_GAINS; ``"model:NAME"``: the shipped gains ``NAME`` (a file in
    ``training/controller/gains``, found from any working directory, e.g. a Ray Tune trial's);
    ``"model:PATH.json"``: the gains in that file. Gains override the defaults. A suffix
    ``+START`` (a name or a path, as the gains) adds a start phase with those gains
    (``"model:teacher_robust+start_rest"``, the teacher from rest and mid-stride).
    """
    if spec != "model" and not spec.startswith("model:"):
        raise ValueError(
            f"a controller is 'model', 'model:NAME' or 'model:GAINS.json' (+START), got {spec!r}"
        )
    name, _, start = spec.partition(":")[2].partition("+")
    if "+" in start:
        raise ValueError(f"a controller has at most one start phase (NAME+START), got {spec!r}")
    gains = _read_gains(name, spec) if name else None
    start_gains = _read_gains(start, spec) if start else None
    return ModelController(gains, limit=limit, start_gains=start_gains)


def _read_gains(name: str, spec: str) -> dict[str, float]:
    """The gains of a shipped name (``training/controller/gains/NAME.json``) or a JSON path."""
    shipped = CONTROLLERS_DIR / f"{name}.json"
    plain = name.replace("_", "").replace("-", "").isalnum()  # a shipped name, never a path
    path = shipped if plain else Path(name)
    if plain and name not in shipped_controllers():
        raise ValueError(f"controller {spec!r}: no shipped gains {name!r}; shipped gains: "
                         f"{shipped_controllers()}")  # fmt: skip
    if not path.is_file():
        known = sorted(p.stem for p in CONTROLLERS_DIR.glob("*.json"))
        raise ValueError(f"controller {spec!r}: no file {path}; shipped gains: {known}")
    return json.loads(path.read_text())


def midstride_state(rate: float = -1.0, theta0: float = -0.2, lean: float = 0.1) -> SimState:
    """The model-2 state of :func:`biped_constraint_env.env.midstride_start` (v2's start)."""
    q, qd = midstride_start(rate, theta0, lean)
    return SimState(0.0, Mode.TOE_PIVOT, 0, q, qd)


def run_episode(env, controller, options=None, seed=None, max_periods=20_000, cap=0):
    """Run one episode (at most ``max_periods``; ``cap`` > 0 stops it at that many steps).

    Returns (steps, hip travel [m], termination reason or None, sim time [s]).
    """
    obs, info = env.reset(seed=seed, options=options)
    controller.reset()
    y0 = info["hip_y"]
    for _ in range(max_periods):
        obs, _, terminated, truncated, info = env.step(controller(obs))
        if terminated or truncated or 0 < cap <= info["steps_completed"]:
            break
    return info["steps_completed"], info["hip_y"] - y0, info["termination_reason"], info["t"]


def main(argv: list[str] | None = None) -> None:
    """``python -m training.controller.model_controller``: run the controller through the env."""
    from biped_constraint_env.env import ConstrainedBipedEnv

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dt", type=float, default=0.005, help="control period [s]")
    ap.add_argument("--preset", default="default")
    ap.add_argument("--seconds", type=float, default=30.0, help="simulated time limit [s]")
    ap.add_argument(
        "--rates",
        type=float,
        nargs="+",
        default=[-1.0],
        help="mid-stride start rates about the stance toe [rad/s]",
    )
    ap.add_argument(
        "--start",
        choices=("rest", "midstride"),
        help="run seeded env resets of this kind (rest: the paper's Fig. 2 posture) instead of "
        "--rates",
    )
    ap.add_argument("--seeds", type=int, default=10, help="reset seeds 0..N-1 with --start")
    ap.add_argument("--cap", type=int, default=0, help="stop an episode at this many steps (0: no)")
    ap.add_argument(
        "--hold",
        action="store_true",
        help="hold the torque through model switches (env default) instead",
    )
    ap.add_argument(
        "--controller",
        default=TEACHER,
        help=f"controller spec (controller_from; default {TEACHER!r}: the teacher, its start "
        "phase from rest included)",
    )
    ap.add_argument("--gains", type=Path, help="JSON {name: value}: the gait's gains instead")
    ap.add_argument("--noise", type=float, default=None, help="reset noise [rad] (env default)")
    a = ap.parse_args(argv)
    ctl = controller_from(a.controller)
    if a.gains:
        ctl = ModelController(
            json.loads(a.gains.read_text()), start_gains=ctl.start_g and dict(ctl.start_g)
        )
    env = ConstrainedBipedEnv(
        preset=a.preset,
        dt=a.dt,
        physics={"stop_at_switch": not a.hold},
        start={
            "kind": a.start or "rest",
            **({} if a.noise is None else {"reset_noise_scale": a.noise}),
        },
    )
    ctl.params, ctl.options = env.params, env.options
    n = int(round(a.seconds / a.dt))
    runs = (
        [(f"seed {s}", None, s) for s in range(a.seeds)]
        if a.start
        else [
            (
                f"rate {r:+.2f} rad/s",
                dict(zip(("q", "qd"), midstride_start(r), strict=True), mode=2),
                None,
            )
            for r in a.rates
        ]
    )
    results = []
    for name, opts, seed in runs:
        steps, dist, reason, t = run_episode(env, ctl, opts, seed, n, a.cap)
        results.append((steps, dist))
        print(f"{name}: {steps} steps, {dist:.2f} m in {t:.2f} s, ended by {reason}", flush=True)
    st, d = np.array(results).T
    print(
        f"{len(results)} episodes: steps mean {st.mean():.1f} std {st.std():.1f} "
        f"min {st.min():.0f}; distance mean {d.mean():.2f} m"
    )


if __name__ == "__main__":
    main()
