"""Pushes, model error, sensor noise and action delay: the env's perturbation options.

Identical in the single and the batched env (both hold one :class:`Perturbations` object for
their N rows, N = 1 for the single env), every draw from the env's own seeded generator (the
single env's ``np_random``, the batched env's per-row generators), in the same order per row:
at a start, the row's model (masses, damping, K) and its first push time; before a period, a
due push's impulse and the time to the next; after a period, the observation noise. With
every option off (the default) nothing is drawn and the env is exactly the nominal one.

* **Pushes** (``push_impulse_ns``: P or a range (lo, hi) drawn per push, signed: > 0
  forward; then ``push_interval_s``: (lo, hi) between pushes, the first one interval after
  the start, or ``push_at_s``: one push at that time or at a time drawn in (lo, hi)): a
  horizontal impulse P [N s] at the hip, applied between two periods through the
  *constrained* impulse map: the joint rates jump by ``dq = M^-1 (J_hip^T P + C^T lam)``
  with the impulses ``lam`` of the current model's contacts, which hold (``C dq = 0``: the
  flat stance foot keeps its angle, the point contact of models 3 and 4 its position). If a
  contact would then have to pull, the strict checks end the episode in the next period, as
  for any event. The joints are free during the impulse (no impulsive motor torque), so the
  hip's velocity changes by about 1 m/s per N s although the biped weighs 5 kg.
  ``info["push_dv_m_s"]`` gives the hip's forward velocity change of the push (0 without).
* **Model error** (``mass_scale``, ``damping_scale``, ``friction_ratio``): per row and
  episode, each link's mass (with its inertia) and each joint's damping times U(lo, hi), and
  the friction ratio K ~ U(lo, hi), stepped in the compiled period (rows differ).
* **Slopes** (``slope_rad``: a constant slope or a range (lo, hi) drawn per episode [rad],
  > 0 rising forward): the ground's slope, gravity turned by it in the ground's frame
  (:attr:`~.model.BipedParams.slope_rad`); drawn with the model, after it.
* **Observation noise** (``obs_noise``): (angle std [rad], rate std [rad/s]) of Gaussian noise
  on the observed q and q-dot (the first 12 entries); the physics is unaffected.
* **Action delay** (``action_delay=1``): each period applies the previous period's action
  (the first period of an episode its own).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .dynamics import nb_mass_matrix
from .hybrid import nb_impulse
from .kinematics import nb_point_jacobian
from .model import MAX_SLOPE_RAD, N_ACTUATED, N_LINKS, SC_HEEL5, SC_TOE5, BipedParams
from .state import FS_T, ST_MODE, ST_SIDE
from .validation import check_int, check_real

HIP_LINK = 3
"""The hip is the proximal end of link 3 (the swing thigh) in the chain's numbering."""
PUSH_IMPULSE_MAX_NS = 1e3
"""Largest accepted push impulse [N s] (the biped weighs 5 kg: 1 N s is about 0.2 m/s)."""
NOISY_OBS = slice(0, 2 * N_LINKS)
"""The observation entries that ``obs_noise`` perturbs: q (6) then q-dot (6)."""


def _range(name: str, value, lo: float, hi: float, unit: str = "") -> tuple[float, float] | None:
    if value is None:
        return None
    if isinstance(value, int | float) and not isinstance(value, bool):
        value = (value, value)
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ValueError(f"{name} must be None, a number or (low, high), got {value!r}")
    a = check_real(name, value[0], lo, hi, unit=unit)
    b = check_real(name, value[1], lo, hi, unit=unit)
    if a > b:
        raise ValueError(f"{name} must be (low, high) with low <= high, got {value!r}")
    return a, b


@dataclass(frozen=True)
class PerturbationSettings:
    """The validated perturbation options of an env (see the module docstring)."""

    push_impulse_ns: tuple[float, float] | None = None
    push_interval_s: tuple[float, float] | None = None
    push_at_s: tuple[float, float] | None = None
    mass_scale: tuple[float, float] | None = None
    damping_scale: tuple[float, float] | None = None
    friction_ratio: tuple[float, float] | None = None
    obs_noise: tuple[float, float] | None = None
    action_delay: int = 0
    slope_rad: tuple[float, float] | None = None

    @property
    def active(self) -> bool:
        """Whether any option is on (else the env is the nominal one and draws nothing)."""
        return self != PerturbationSettings()

    @property
    def randomises_model(self) -> bool:
        """Whether rows draw their own robot at every start."""
        return any(r is not None for r in (self.mass_scale, self.damping_scale,
                                           self.friction_ratio, self.slope_rad))  # fmt: skip


def check_perturbation_settings(
    push_impulse_ns=None,
    push_interval_s=None,
    push_at_s=None,
    mass_scale=None,
    damping_scale=None,
    friction_ratio=None,
    obs_noise=None,
    action_delay=0,
    slope_rad=None,
) -> PerturbationSettings:
    """The validated options; a push needs an impulse and either an interval or a time."""
    imp = _range("push_impulse_ns", push_impulse_ns, -PUSH_IMPULSE_MAX_NS, PUSH_IMPULSE_MAX_NS,
                 " [N s]")  # fmt: skip
    interval = _range("push_interval_s", push_interval_s, 1e-3, 1e4, " [s]")
    at = _range("push_at_s", push_at_s, 0.0, 1e4, " [s]")
    if imp is not None and (interval is None) == (at is None):
        raise ValueError("push_impulse_ns needs exactly one of push_interval_s and push_at_s")
    if imp is None and (interval is not None or at is not None):
        raise ValueError("push_interval_s / push_at_s need push_impulse_ns")
    noise = None
    if obs_noise is not None:  # (angle std, rate std), not a range
        if not isinstance(obs_noise, list | tuple) or len(obs_noise) != 2:
            raise ValueError(f"obs_noise must be None or (angle std, rate std), got {obs_noise!r}")
        noise = (check_real("obs_noise", obs_noise[0], 0.0, 1.0, unit=" [rad]"),
                 check_real("obs_noise", obs_noise[1], 0.0, 100.0, unit=" [rad/s]"))  # fmt: skip
    return PerturbationSettings(
        push_impulse_ns=imp,
        push_interval_s=interval,
        push_at_s=at,
        mass_scale=_range("mass_scale", mass_scale, 0.1, 10.0),
        damping_scale=_range("damping_scale", damping_scale, 0.0, 10.0),
        friction_ratio=_range("friction_ratio", friction_ratio, 0.0, 10.0),
        obs_noise=noise,
        action_delay=check_int("action_delay", action_delay, 0, 1),
        slope_rad=_range("slope_rad", slope_rad, -MAX_SLOPE_RAD, MAX_SLOPE_RAD, " [rad]"),
    )


def draw_params(nominal: BipedParams, s: PerturbationSettings, rng) -> BipedParams:
    """A robot drawn around ``nominal``: masses, damping (per link), K and the slope."""
    links = list(nominal.links)
    if s.mass_scale is not None:
        f = rng.uniform(*s.mass_scale, N_LINKS)
        links = [
            dataclasses.replace(k, mass_kg=k.mass_kg * x) for k, x in zip(links, f, strict=True)
        ]
    if s.damping_scale is not None:
        f = rng.uniform(*s.damping_scale, N_LINKS)
        links = [dataclasses.replace(k, damping_nms_per_rad=k.damping_nms_per_rad * x)
                 for k, x in zip(links, f, strict=True)]  # fmt: skip
    k = nominal.friction_ratio if s.friction_ratio is None else rng.uniform(*s.friction_ratio)
    slope = nominal.slope_rad
    if s.slope_rad is not None:
        lo, hi = s.slope_rad
        slope = lo if lo == hi else rng.uniform(lo, hi)
    return dataclasses.replace(
        nominal, links=tuple(links), friction_ratio=float(k), slope_rad=float(slope)
    )


def hip_impulse(params: BipedParams, mode: int, side: int, q: np.ndarray, impulse) -> np.ndarray:
    """The joint-rate jump (6,) of a hip impulse (y, z) [N s] with the model's contacts held.

    ``dq = M^-1 J_hip^T P`` projected, in the mass metric, onto the rates that keep the
    current model's contacts (:func:`~.hybrid.nb_impulse`, the plastic impact map's solve):
    model 1 keeps the stance foot's angle; model 2 (on the stance toe, the chain's root)
    keeps nothing more; model 3 keeps the swing heel's position, model 4 the foot's angle and
    the swing toe's position.
    """
    ch = params.chain(side)
    pk, sc = ch.packed, ch.packed_scalars
    jac = nb_point_jacobian(pk, q, HIP_LINK, 0.0)
    gen = jac[0] * impulse[0] + jac[1] * impulse[1]  # J_hip^T P
    v = np.linalg.solve(nb_mass_matrix(pk, q), gen)
    rows = []
    if mode in (1, 4):
        e = np.zeros(N_LINKS)
        e[0] = 1.0
        rows.append(e)
    if mode in (3, 4):
        j = nb_point_jacobian(pk, q, 5, float(sc[SC_HEEL5 if mode == 3 else SC_TOE5]))
        rows += [j[0], j[1]]
    if not rows:
        return v
    return nb_impulse(pk, q, v, np.array(rows))


class Perturbations:
    """The perturbations of N env rows (their push times, held actions and robots)."""

    def __init__(self, n: int, settings: PerturbationSettings, nominal: BipedParams, buf):
        """For ``n`` rows stepping ``buf`` (:class:`~.period.EnvBuffers`)."""
        self.s = settings
        self.nominal = nominal
        self.buf = buf
        self.params = [nominal] * n
        self.next_push = np.full(n, np.inf)
        self.held = np.zeros((n, N_ACTUATED))
        self.has_held = np.zeros(n, bool)
        self.push_dv = np.zeros(n)
        self.push_ns = np.zeros(n)
        self.active = settings.active

    def start(self, idx, rngs) -> None:
        """New episodes in rows ``idx`` (row ``idx[k]`` drawing from ``rngs[k]``)."""
        if not self.active:  # the nominal env: nothing to draw or hold
            return
        s = self.s
        for i, rng in zip(np.asarray(idx), rngs, strict=True):
            if s.randomises_model:
                self.params[i] = draw_params(self.nominal, s, rng)
                self.buf.set_params(i, self.params[i])
            t = self.buf.sim.fst[i, FS_T]
            if s.push_at_s is not None:  # one push, at a time drawn in the range
                lo, hi = s.push_at_s
                self.next_push[i] = lo if lo == hi else rng.uniform(lo, hi)
            elif s.push_interval_s is not None:
                self.next_push[i] = t + rng.uniform(*s.push_interval_s)
            self.has_held[i] = False

    def before_period(self, actions: np.ndarray, rngs, rows) -> np.ndarray:
        """Apply the due pushes of the stepped ``rows``; the actions (n, 5) to apply (delayed).

        ``rngs[i]``: row i's generator.
        """
        sim = self.buf.sim
        self.push_dv[:] = 0.0
        self.push_ns[:] = 0.0
        if self.s.push_impulse_ns is not None:
            for i in rows:
                if sim.fst[i, FS_T] + 1e-12 < self.next_push[i]:
                    continue
                rng = rngs[i]
                p = rng.uniform(*self.s.push_impulse_ns)
                mode, side = int(sim.ist[i, ST_MODE]), int(sim.ist[i, ST_SIDE])
                q = sim.q[i].copy()
                dq = hip_impulse(self.params[i], mode, side, q, (p, 0.0))
                sim.qd[i] += dq
                jac = nb_point_jacobian(self.params[i].chain(side).packed, q, HIP_LINK, 0.0)
                self.push_dv[i] = float(jac[0] @ dq)
                self.push_ns[i] = p
                if self.s.push_interval_s is None:
                    self.next_push[i] = np.inf
                else:
                    self.next_push[i] = sim.fst[i, FS_T] + rng.uniform(*self.s.push_interval_s)
        if not self.s.action_delay:
            return actions
        rows = np.asarray(rows, np.int64)
        out = actions.copy()
        late = rows[self.has_held[rows]]
        out[late] = self.held[late]
        self.held[rows] = actions[rows]
        self.has_held[rows] = True
        return out

    def observe(self, obs: np.ndarray, rngs, rows) -> np.ndarray:
        """The observations (n, d) with sensor noise on ``rows`` (a copy; others unchanged).

        Every observation an env returns, a reset's included, goes through this once.
        """
        if self.s.obs_noise is None:
            return obs
        a, r = self.s.obs_noise
        scale = np.concatenate([np.full(N_LINKS, a), np.full(N_LINKS, r)])
        obs = obs.copy()
        for i in rows:
            obs[i, NOISY_OBS] += scale * rngs[i].standard_normal(2 * N_LINKS)
        return obs


def perturbation_settings(options: dict | None) -> PerturbationSettings:
    """The env's ``perturbations`` kwarg (a dict of the options above, or None) validated."""
    if options is None:
        return PerturbationSettings()
    if not isinstance(options, dict):
        raise ValueError(f"perturbations must be a dict of options or None, got {options!r}")
    names = [f.name for f in dataclasses.fields(PerturbationSettings)]
    unknown = sorted(set(options) - set(names))
    if unknown:
        raise ValueError(f"perturbations: unknown option(s) {unknown}; known: {names}")
    return check_perturbation_settings(**options)
