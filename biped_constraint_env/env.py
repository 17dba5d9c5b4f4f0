"""ConstrainedBiped-v0: a thin Gymnasium adapter over the four-model hybrid simulator.

The physics lives in :mod:`.simulator`; the action check in :mod:`.actions`, the observation
in :mod:`.observation`, starts in :mod:`.starts`, rewards in :mod:`.rewards` and the task
settings in :mod:`.tasks`, all shared with the batched :mod:`.vector_env`.
"""

from __future__ import annotations

import inspect
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .actions import (
    PD_BOUND,
    TORQUE_ACTIONS,
    TORQUE_LIMIT_NM,
    action_config,
    check_action_settings,
    check_pd_dt,
    validate_action,
)
from .clock import ContactClock
from .model import N_ACTUATED, BipedParams, paper_biped
from .modes import EventCode
from .observation import observation_space
from .period import EnvBuffers
from .perturbations import Perturbations, perturbation_settings
from .rewards import (
    REWARD_TERMS,
    TERMINATION_FALL,
    TERMINATION_NON_FINITE,
    check_fall_height,
    reward_config,
    reward_weights,
)
from .simulator import SimState, evaluate, keypoints
from .starts import (
    NOMINAL_POSTURE_RAD,
    RESET_NOISE_SCALE_RAD,
    check_start_settings,
    check_start_state,
    draw_starts,
    state_from_options,
)
from .state import STATUS_NONFINITE, STATUS_TERMINATED
from .tasks import resolve_options, resolve_task
from .tracking import PD_RANGE_RAD, TRACKING_TERMS, Tracking, check_tracking_settings
from .validation import check_bool, check_names, check_seeds

TRACK_KEYS = tuple(f"track_{t}" for t in TRACKING_TERMS)
"""The tracking reward's terms in ``info`` (``reward="tracking"``)."""


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
    models. Conventions (angles, signs): docs/conventions.md.

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
    | 0-5 | theta0, q1..q5 (docs/conventions.md, current numbering), wrapped | -pi | pi | rad |
    | 6-11 | their rates | -1e3 | 1e3 | rad/s |
    | 12 | hip y relative to the stance toe | -10 | 10 | m |
    | 13 | hip height z | -10 | 10 | m |
    | 14-15 | hip velocity (y, z) | -1e3 | 1e3 | m/s |
    | 16 | stance leg (0 = leg A, 1 = leg B) | 0 | 1 | - |
    | 17-20 | model one-hot (paper models 1, 2, 3, 4) | 0 | 1 | - |
    | 21 | stance toe vertical force (F_R in models 1, 4) | -1e5 | 1e5 | N |
    | 22 | stance heel vertical force (F_L in models 1, 4; 0 in 2, 3) | -1e5 | 1e5 | N |
    | 23 | point-contact normal force f_n (models 3, 4; else 0) | -1e5 | 1e5 | N |

    With ``phase_obs=True`` two entries follow (:mod:`.clock`): 24, the first-step flag (1
    from a start at rest until its first step completes), and 25, the time in the current
    model [s] (counted in control periods, clipped to 2 s): ``Box((26,))``.

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
    ``start="midstride"`` (the walking task): model 2, leg A on its toe, turning forward about
    it: :func:`~.starts.midstride_start` with the rate uniform in
    ``MIDSTRIDE_RATE_RANGE_RAD_S`` (-1.1 to -0.9 rad/s) and the heel-up angle theta0 uniform in
    ``MIDSTRIDE_THETA0_RANGE_RAD`` (-0.25 to -0.15 rad). ``start="rest"`` (``task="paper"``'s
    default; with the walking task, the paper's scene): model 1, leg A standing at rest in
    ``posture`` (default ``NOMINAL_POSTURE_RAD``, the paper's Fig. 2). ``start="mixed"``: rest
    or mid-stride, 1/2 each (for learning both starts). All add
    uniform noise in ``[-reset_noise_scale, reset_noise_scale]`` (0.01 rad) to q1..q5; the
    stance toe is at y = 0. ``reset(options={"q", "qd", "mode", "stance_side", "root_y"})``
    starts from any state in the coordinates of docs/conventions.md (validated: points on or
    above the ground, model constraints satisfied; a ``ValueError`` names what is wrong).

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
    By the time limit only: ``max_episode_steps=6000`` control periods at registration (30 s
    of the walking task; 120 s with ``task="paper"``'s 20 ms).

    ## Arguments
    Every argument is validated (a ``ValueError`` names it). ``task`` sets the defaults of
    ``preset``, ``dt``, ``stop_at_switch`` and ``start`` (:data:`~.tasks.TASKS`); each given
    explicitly overrides the task's value.

    | Parameter | Default (``task="walk"``) | ``task="paper"`` | Description (unit) |
    |-----------|---------|---------|--------------------|
    | task | "walk" | | "walk", "track" (learning from the reference walk) or "paper" |
    | preset | "default" | "paper" | "default" (error-controlled RK4_LIMEX), "fixed_step" |
    | | | | (RK4_LIMEX, 2.5 ms), "fast" (RK2, 5 ms), "paper" |
    | dt | 0.005 | 0.02 | control period [s] |
    | stop_at_switch | True | False | end a period just after a model switch |
    | start | "midstride" | "rest" | start distribution (Starting State) |
    | integrator, substeps, impact, locate_events, jdot, strict, | None | | override one |
    | heel_force_includes_foot_weight, step_tol | | | (``SimOptions``); ``substeps`` per |
    | | | | period (a preset keeps its longest step at any ``dt``) |
    | params | paper_biped() | | the robot (``BipedParams``) |
    | torque_limit_nm | 150 | | action bound [N m] |
    | out_of_range | "clip" | | "clip" or "raise" |
    | forward_reward_weight, alive_bonus, switch_bonus, | 1, 0.5, 1, | | reward weights |
    | step_bonus, ctrl_cost_weight | 5, 0.1 | | (Rewards) |
    | reset_noise_scale | 0.01 | | uniform noise on q1..q5 [rad] |
    | fall_hip_height_m | None | | end the episode when the hip is below [m] |
    | posture | NOMINAL_POSTURE_RAD | | start posture of ``start="rest"`` [rad] |
    | phase_obs | False | | append the contact clock's phase (below) to the observation |
    | reward | "env" | | "env" (Rewards) or "tracking" (a reference walk's; below) |
    | reference | None | | the reference walk: "midstride", "rest" or an npz path |
    | | | | (None: "rest" for the rest and mixed starts, else "midstride") |
    | rsi | 0.0 | | fraction of resets at reference states (reference-state starts) |
    | action | "torque" | | "torque" or "pd": PD targets in [-1, 1]^5 (below) |
    | pd_around, pd_range | "fixed", 1.0 | | targets about ``pd_pose`` or the reference [rad] |
    | pd_pose, pd_gain_scale | Fig. 2, 1.0 | | the fixed pose q1..q5 [rad]; Kp x s, Kd x sqrt(s) |
    | pd_offset | zeros | | constant offset of the PD targets q1..q5 [rad] |
    | pd_dt | min(5 ms, dt) | | physics step of the PD law [s]; divides dt (= dt: held) |
    | perturbations | None | | dict: pushes, model error, sensor noise, action delay |
    |  |  |  | (:mod:`.perturbations`; one kwarg for the group: eight options that only |
    |  |  |  | robustness studies set, validated together) |
    | reference_obs | False | | append the reference's q and q-dot at the clock (12) |
    | render_mode | None | | "rgb_array" or "human" |

    ## Learning
    The walking task's feasible set is thin: random or zero torques end an episode in its first
    period (``stance_toe_pulls``), so SB3's defaults learn nothing on it. ``task="track"`` sets
    up the task that PPO learns from a random network (docs/sb3.md, a plain-SB3 script).

    ## Tracking task
    Options for learning from a reference walk (:mod:`.tracking`; the default env uses none):
    ``reward="tracking"`` is a DeepMimic-style sum of exponential kernels of the pose, rate, hip
    height and hip speed errors against the reference at the contact clock, plus 1 per
    completed step (``info["track_<term>"]``); ``rsi`` starts that fraction of the episodes at
    recorded reference states; ``action="pd"`` makes the action five joint targets, tracked by
    the PD law ``Kp (target - q) + Kd (rate - q-dot)`` with gains ``PD_KP``, ``PD_KD``: the
    targets hold over the control period and the law, clipped to the torque limit, is evaluated
    at every physics step ``pd_dt`` inside it, as legged-robot envs do (decimation; 20 ms
    periods apply their targets through four 5 ms PD updates). ``info["torque"]`` gives the
    period's time-mean torque; the control cost is the time mean of sum(tau^2).
    ``reference_obs`` shows the reference to the policy. The clock restarts at every model
    switch; a start follows its own reference's first step (rest with "rest", mid-stride with
    "midstride").

    ## Version History
    * v0 (unreleased, the only id): accurate physics and the walking task by default; the
      paper's setting is ``task="paper"``. Changed: a preset's substeps now scale with ``dt``
      (the walking task integrates RK4 x 4 per 5 ms, the documented 1.25 ms, not x 16).
      Changed: the default preset is error-controlled RK4_LIMEX (``"rk4_limex_adaptive"``,
      ``step_tol`` 2e-4, steps up to the control period), in place of RK4 x 16; the fixed-step
      RK4_LIMEX x 8 per 20 ms is ``preset="fixed_step"``. Added: ``step_tol``. Changed: every
      argument is checked by name (no silent coercion), ``step()`` before ``reset()`` or after
      an episode's end raises, a start drawn below the ground is drawn again. Added:
      ``start="mixed"``, ``phase_obs``; the batched env's ``num_threads`` (default 1).
      Added: the tracking task's options (``reward``, ``reference``, ``rsi``, ``action``,
      ``pd_around``, ``pd_range``, ``pd_pose``, ``pd_gain_scale``, ``pd_offset``,
      ``reference_obs``); the defaults leave the env as it was. Changed: PD targets hold
      over the control period with the PD law at every physics step ``pd_dt`` (added; default
      5 ms, or dt when shorter), in compiled code; before, the PD torque of the period's
      first state was held over the period, which ``pd_dt=dt`` keeps (at the walking task's
      5 ms both are the same law, bit for bit). Changed: ``reset(seed=...)`` refuses a seed
      that is not an int >= 0 (a float, a bool). Added: ``perturbations`` (pushes through the
      constrained impulse map, per-row masses, damping and K, sensor noise, action delay).
      Added: ``task="track"``, the tracking settings of the from-scratch recipe as one task
      (``reward="tracking"``, ``rsi=0.5``, ``action="pd"``, ``pd_around="reference"``, the
      stance-ankle ``pd_offset`` and ``phase_obs``), each still overridable.

    Example:
        >>> import gymnasium as gym
        >>> import biped_constraint_env
        >>> env = gym.make("ConstrainedBiped-v0")
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, info["mode"]
        ((24,), 2)
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 50}

    def __init__(
        self,
        params: BipedParams | None = None,
        task: str = "walk",
        preset: str | None = None,
        dt: float | None = None,
        integrator: str | None = None,
        substeps: int | None = None,
        impact: str | None = None,
        locate_events: bool | None = None,
        jdot: str | None = None,
        strict: bool | None = None,
        heel_force_includes_foot_weight: bool | None = None,
        step_tol: float | None = None,
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
        start: str | None = None,
        phase_obs: bool | None = None,
        reward: str | None = None,
        reference: str | None = None,
        rsi: float | None = None,
        action: str | None = None,
        pd_around: str | None = None,
        pd_range: float = PD_RANGE_RAD,
        reference_obs: bool = False,
        pd_gain_scale: float = 1.0,
        pd_pose=None,
        pd_offset=None,
        pd_dt: float | None = None,
        perturbations: dict[str, Any] | None = None,
        render_mode: str | None = None,
        **unknown: Any,
    ):
        """Create the environment (see the class docstring, Arguments)."""
        check_names("argument(s) of ConstrainedBiped-v0", unknown, ENV_ARGUMENTS)
        self.params = params if params is not None else paper_biped()
        self.task = task
        settings = resolve_task(
            task, preset=preset, dt=dt, stop_at_switch=stop_at_switch, start=start,
            reward=reward, rsi=rsi, action=action, pd_around=pd_around, pd_offset=pd_offset,
            phase_obs=phase_obs,
        )  # fmt: skip
        dt, start = settings["dt"], settings["start"]
        reward, rsi, action = settings["reward"], settings["rsi"], settings["action"]
        pd_around, pd_offset = settings["pd_around"], settings["pd_offset"]
        phase_obs = settings["phase_obs"]
        self.options = resolve_options(
            settings["preset"],
            dt,
            dict(
                integrator=integrator,
                substeps=substeps,
                impact=impact,
                locate_events=locate_events,
                jdot=jdot,
                strict=strict,
                heel_force_includes_foot_weight=heel_force_includes_foot_weight,
                step_tol=step_tol,
                stop_at_switch=settings["stop_at_switch"],
            ),
        )
        self.dt = float(dt)
        self.torque_limit_nm, self.out_of_range = check_action_settings(
            torque_limit_nm, out_of_range
        )
        self.weights = reward_weights(
            forward_reward_weight, alive_bonus, switch_bonus, step_bonus, ctrl_cost_weight
        )
        self.fall_hip_height_m = check_fall_height(fall_hip_height_m)
        self.start, self.posture, self.reset_noise_scale = check_start_settings(
            self.params, start, posture, reset_noise_scale
        )
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.dt))}
        self.tracking_settings = check_tracking_settings(
            self.start, reward, reference, rsi, action, pd_around, pd_range, reference_obs,
            pd_gain_scale, pd_pose, pd_offset,
        )  # fmt: skip
        ts = self.tracking_settings
        self.pd_action = ts["action"] == "pd"
        self.action_bound = 1.0 if self.pd_action else self.torque_limit_nm
        self.action_bound_name = PD_BOUND if self.pd_action else "torque limit"
        bound = self.action_bound
        self.action_space = spaces.Box(-bound, bound, (N_ACTUATED,), np.float32)
        self.phase_obs = check_bool("phase_obs", phase_obs)
        self.reference_obs = ts["reference_obs"]
        self.observation_space = observation_space(self.phase_obs, self.reference_obs)
        self.pd_substeps = check_pd_dt(pd_dt, self.dt) if self.pd_action else 0
        self._clock, self.tracking = make_clock_and_tracking(1, self)
        self._buf = EnvBuffers(
            1,
            self.params,
            self.options,
            self.dt,
            reward_config(self.weights, self.torque_limit_nm, self.fall_hip_height_m),
            action_config(self.action_bound, self.out_of_range),
            pcfg=self.action_mapping(),
        )
        if self.pd_action:  # constant bases about a fixed pose: set once
            self._buf.tgt[:], self._buf.rate[:] = self.tracking.bases(1)
        self.perturbation_settings = perturbation_settings(perturbations)
        self._perturb = Perturbations(1, self.perturbation_settings, self.params, self._buf)
        self._perturbed = self.perturbation_settings.active  # (looked up once per step)
        self._noisy = self.perturbation_settings.obs_noise is not None
        self._pushes = self.perturbation_settings.push_impulse_ns is not None
        self._sim, self._obs, self._hip = self._buf.sim, self._buf.obs, self._buf.hip
        self._renderer = None
        self._needs_reset = True  # until a reset succeeds, and again after a termination
        self._track_reward = self.tracking_settings["reward"] == "tracking"

    def action_mapping(self) -> np.ndarray:
        """The compiled period's action mapping (:func:`~.actions.pd_config`)."""
        if not self.pd_action:
            return TORQUE_ACTIONS
        return self.tracking.pd_config(self.pd_substeps)

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
        if seed is not None:
            check_seeds(seed, 1)  # an int >= 0: not a float, a bool or a list
        super().reset(seed=seed)
        self._needs_reset = True  # stays so if this reset is refused
        slot = np.zeros(1, np.int64)
        if options is not None and not (isinstance(options, dict) and not options):
            state = state_from_options(options)
            check_start_state(self.params, state)
            forces = evaluate(self.params, state, np.zeros(N_ACTUATED), self.options)[1]
            self._sim.set(0, state, forces)
            start_clocks(self._clock, self.tracking, slot, self._sim)
        else:
            draw_episode_starts(self, self._sim, slot, [self.np_random], self._clock, self.tracking)
        self._perturb.start(slot, [self.np_random])
        self._needs_reset = False
        self._observe()
        info = self._info((), (0.0,) * len(REWARD_TERMS), None)
        if self._track_reward:
            info.update(dict.fromkeys(TRACK_KEYS, 0.0))
        if self.render_mode == "human":
            self.render()
        return self._observation(), info

    def step(self, action):
        """Apply the torques for one control period (see the class docstring)."""
        a = action if isinstance(action, np.ndarray) else np.asarray(action)
        buf = self._buf
        sim = buf.sim
        if self._needs_reset or a.shape != (N_ACTUATED,) or a.dtype.kind not in "fiu":
            if self._needs_reset:
                raise RuntimeError(
                    "step() called before reset() or after the episode ended; call reset()"
                )
            validate_action(a, self.action_bound, self.out_of_range, self.action_bound_name)
        if self.pd_action and self.tracking.pd_follows_reference:
            buf.tgt[:1], buf.rate[:1] = self.tracking.bases(1)
        if self._perturbed:  # pushes due now; the delayed action
            a = self._perturb.before_period(a[None, :].astype(np.float64), [self.np_random], [0])[0]
        buf.act[0] = a  # as float64; checked (and clipped) in the compiled period
        steps0 = sim.ist[0, 2]
        if buf.period():
            validate_action(a, self.action_bound, self.out_of_range, self.action_bound_name)
            raise AssertionError(f"the compiled action check refused {a}, validate_action not")
        status = sim.status[0]
        events = sim.events_of(0) if sim.n_events[0] else ()
        reason = None
        if status == STATUS_TERMINATED:
            reason = next(e.code.name.lower() for e in events if e.terminal)
        elif status == STATUS_NONFINITE:
            reason = TERMINATION_NON_FINITE
        elif buf.fell[0]:
            reason = TERMINATION_FALL
        *terms, reward = buf.rew[0].tolist()
        info = self._info(events, terms, reason)
        if reason is not None:
            self._needs_reset = True
        if self.render_mode == "human":
            self.render()
        if self.pd_action:  # the time-mean PD torque of the period
            info["torque"] = buf.act[0].copy()
        if self._pushes:
            info["push_impulse_ns"] = float(self._perturb.push_ns[0])
            info["push_dv_m_s"] = float(self._perturb.push_dv[0])
        if self._clock is None:
            obs = self._observation() if self._noisy else buf.obs[0].copy()
            return obs, reward, reason is not None, False, info
        self._clock.advance(sim.ist[:1, 0], sim.ist[:1, 2])
        if self.tracking is not None:
            self.tracking.after_period(sim.ist[:1, 2])
        if self._track_reward:
            track = self.tracking.reward(
                sim.q[:1], sim.qd[:1], self._hip[:1], sim.ist[:1, 2] - steps0,
                np.array([reason is None]),
            )[0]  # fmt: skip
            info.update(zip(TRACK_KEYS, track[:-1].tolist(), strict=True))
            reward = float(track[-1])
        return self._observation(), reward, reason is not None, False, info

    def _observation(self) -> np.ndarray:
        """The observation (with the phase and reference entries, and noise, when asked for)."""
        obs = (
            self._obs
            if self._clock is None
            else observations(self._obs, self._clock, self.tracking, self)
        )
        return self._perturb.observe(obs, [self.np_random], [0])[0].copy()

    def _observe(self) -> None:
        self._buf.observe()

    def _info(self, events, terms, reason) -> dict[str, Any]:
        """The info dict; ``terms``: the reward terms' values in REWARD_TERMS order."""
        mode, side, steps, _ = self._sim.ist[0].tolist()
        switches, events = event_infos(events) if events else ((), ())
        forward, alive, switch, step, ctrl = terms  # REWARD_TERMS order
        return {
            "mode": mode,
            "stance_side": side,
            "steps_completed": steps,
            "t": self._sim.fst.item(0),  # row 0, column 0 (fastest scalar read)
            "hip_y": self._hip.item(0),
            "switches": switches,
            "events": events,
            "termination_reason": reason,
            "reward_forward": forward,
            "reward_alive": alive,
            "reward_switch": switch,
            "reward_step": step,
            "reward_ctrl": ctrl,
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


def event_infos(events) -> tuple[tuple, tuple]:
    """The ``info`` entries ``switches`` and ``events`` of a period's events (both envs).

    ``switches``: (t, from, to) of each model switch; ``events``: (t, name, terminal) of each.
    """
    switches = tuple(
        (e.t, e.mode_from, e.mode_to) for e in events if e.code == EventCode.MODE_SWITCH
    )
    return switches, tuple((e.t, e.code.name.lower(), e.terminal) for e in events)


def make_clock_and_tracking(n: int, env: ConstrainedBipedEnv):
    """The contact clock (or None) and :class:`~.tracking.Tracking` (or None) of ``n`` envs.

    A clock is kept when the phase is observed or a tracking option needs the reference; the
    tracking object when one does, or for PD-target actions.
    """
    ts = env.tracking_settings
    needs_clock = env.phase_obs or ts["needs_reference"]
    clock = ContactClock(n, env.dt) if needs_clock else None
    tracking = None
    if ts["needs_reference"] or ts["action"] == "pd":
        tracking = Tracking(n, ts, env.torque_limit_nm, clock)
    return clock, tracking


def draw_episode_starts(env: ConstrainedBipedEnv, sim, idx: np.ndarray, rngs, clock, tracking):
    """Sampled starts of slots ``idx`` (slot ``idx[k]`` draws from ``rngs[k]``), clocks started.

    ``env`` gives the start settings. With a tracking reference, its reference-state starts and
    clock placement (:meth:`~.tracking.Tracking.draw_starts`); else the env's own starts.
    """
    if tracking is not None and tracking.ref is not None:
        tracking.draw_starts(
            env.params, env.options, sim, idx, rngs, env.start, env.posture,
            env.reset_noise_scale,
        )  # fmt: skip
        return
    draw_starts(
        env.params, env.options, sim, idx, rngs, env.start, env.posture, env.reset_noise_scale
    )
    start_clocks(clock, None, idx, sim)


def start_clocks(clock, tracking, idx: np.ndarray, sim) -> None:
    """Start the clocks of slots ``idx`` at their current states (placed on the reference)."""
    if clock is None:
        return
    if tracking is not None and tracking.ref is not None:
        tracking.start_given(idx, sim)
    else:
        clock.start(idx, sim.ist[idx, 0], sim.qd[idx])


def observations(obs: np.ndarray, clock, tracking, env) -> np.ndarray:
    """(n, dim) observations: base, phase (``phase_obs``), reference (``reference_obs``)."""
    parts = [obs]
    if env.phase_obs:
        parts.append(clock.features())
    if env.reference_obs:
        parts.append(tracking.observation())
    return np.concatenate(parts, axis=1) if len(parts) > 1 else obs.copy()


ENV_ARGUMENTS: tuple[str, ...] = tuple(
    name
    for name, p in inspect.signature(ConstrainedBipedEnv.__init__).parameters.items()
    if name != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD
)
"""The keyword arguments of ``gym.make("ConstrainedBiped-v0", ...)`` (a misspelt one raises a
ValueError listing these)."""
