"""ConstrainedBiped-v0: a thin Gymnasium adapter over the four-model hybrid simulator.

The physics lives in :mod:`.simulator`; the settings are validated once in :mod:`.settings`
and everything around the compiled period is :mod:`.core`'s, shared with the batched
:mod:`.vector_env` (this env is its one-row case): this module adds Gymnasium's single-env API
and rendering.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .actions import validate_action
from .command import check_commands, split_reset_options
from .core import EnvCore
from .model import N_ACTUATED
from .settings import ENV_ARGUMENTS as SETTINGS_ARGUMENTS
from .settings import make_settings
from .simulator import SimState, keypoints
from .starts import state_from_options
from .validation import check_seeds


class ConstrainedBipedEnv(gym.Env):
    r"""Planar six-link biped whose ground contact is a constraint (Maeba et al. 2013).

    To learn with an off-the-shelf RL library, start from ``examples/train_sb3.py``
    (docs/sb3.md): the default task keeps the strict contact checks, on which random or zero
    torques end every episode in its first control period (``ep_len_mean`` 1); with 20 ms
    torques, the gait reward (``reward={"kind": "gait", ...}``) and the env's stride starts,
    plain SB3 PPO learns to walk from a random network with no recorded motion, and
    ``training/configs/`` holds the recipes.

    ## Description
    The robot of the paper "Bipedal Locomotion Model Based on Constraint Condition by
    Newton-Euler Method": a serial chain of six rods (stance foot, shank, thigh, thigh, shank,
    swing foot; 5 kg in all) in the vertical y-z plane, rooted at the stance toe. Its motion
    switches among the paper's four models (1: stance foot flat; 2: stance toe pivot; 3: toe
    + swing heel; 4: new stance foot flat + old toe), each with its own unknowns, solved by
    the Newton-Euler method with the contacts as constraints (docs/conventions.md). One walking
    step is the cycle 1 -> 2 -> 3 -> 4 -> 1; the legs swap roles at 3 -> 4. The agent applies the
    five joint torques and should walk forward (+y) as far as it can without leaving the four
    models. Conventions (angles, signs): docs/conventions.md.

    ## Action Space
    ``Box(-torque_limit_nm, torque_limit_nm, (5,), float32)``, torques in N m, held over
    the control period ``dt``, in the *current* numbering (index 0 acts at the stance ankle).
    With ``physics={"stop_at_switch": True}`` (the walking task's) a period ends early, just
    after a model switch (its impact and, at 3 -> 4, the renumbering applied), so that the next
    action acts from the switch itself: the paper changes the torque at the switch, and a torque
    held past the 3 -> 4 renumbering would otherwise act on other joints. ``info["t"]`` gives the
    time, ``info["hip_y"]`` the hip's and ``info["root_y"]`` the stance toe's world y [m].

    | Num | joint | acts on (link i vs i-1)        | limit [N m] | sign |
    |-----|-------|--------------------------------|-------------|------|
    | 0   | 1     | stance shank vs stance foot    | 150         | + counter-clockwise on link i |
    | 1   | 2     | stance thigh vs stance shank   | 150         | same |
    | 2   | 3     | swing thigh vs stance thigh    | 150         | same |
    | 3   | 4     | swing shank vs swing thigh     | 150         | same |
    | 4   | 5     | swing foot vs swing shank      | 150         | same |

    Out-of-range torques are clipped (``action={"out_of_range": "clip"}``, default) or refused
    with a ``ValueError`` (``"raise"``). NaN, inf, a wrong shape or a non-numeric dtype raise
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

    With ``observation=["phase"]`` two entries follow (:mod:`.clock`): 24, the first-step flag (1
    from a start at rest until its first step completes), and 25, the time in the current
    model [s] (counted in control periods, clipped to 2 s): ``Box((26,))``. With
    ``observation=["gravity"]`` two entries follow: the direction of gravity in the ground's
    frame, (-sin a, -cos a) on a slope of a (``gravity_y``, ``gravity_z``; legged-robot RL's
    projected gravity, an IMU's reading); without it a slope shows only in the motion. Blocks
    follow in the order listed; the command's entry comes last.

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
    1.0, 5.0, 0.1; ``reward={"weights": {"forward", "alive", "switch", "step", "ctrl"}}``
    sets them. There is no fall penalty (it makes agents timid); the small alive and switch
    bonuses reward staying inside the models and moving through the cycle, which the forward
    term alone does not (it pays for a lunge). ``info`` contains each term.

    ## Starting State
    ``start="midstride"`` (the walking task): model 2, leg A on its toe, turning forward about
    it: :func:`~.starts.midstride_start` with the rate uniform in
    ``MIDSTRIDE_RATE_RANGE_RAD_S`` (-1.1 to -0.9 rad/s) and the heel-up angle theta0 uniform in
    ``MIDSTRIDE_THETA0_RANGE_RAD`` (-0.25 to -0.15 rad). ``start="rest"`` (``task="paper"``'s
    default; with the walking task, the paper's scene): model 1, leg A standing at rest in
    ``posture`` (default ``NOMINAL_POSTURE_RAD``, the paper's Fig. 2). ``start="mixed"``: rest
    or mid-stride, 1/2 each (for learning both starts). ``start="stride"``: the mid-stride start
    with the swing leg drawn along its swing (its thigh from 0.3 rad behind to 0.4 rad in front
    of straight down, the knee bent 0.05-0.6 rad, the thigh turning forward at 0-2 rad/s, the
    foot level), or half of the draws its model-1 counterpart on the flat stance foot (the leg
    leaning -0.3 to 0.3 rad, turning forward at 0.2-0.6 rad/s; ``STRIDE_*`` in :mod:`.starts`):
    a training start spread over the step's swing with no recorded motion. ``start="stand"``:
    model 4 at rest, both feet down (:func:`~.starts.stand_start`: the front foot flat, the
    rear foot on its toe 0.85-1.15 m behind the front toe with its heel up 0.05-0.2 rad, the
    hip 0.45-0.75 m behind the front toe at 2.65-2.8 m, knees bent forward; ``STAND_*`` in
    :mod:`.starts`): standing. ``start="brake"``: the standing start's draw moving, its hip
    forward at 0-0.8 m/s (``BRAKE_HIP_SPEED_RANGE_M_S``), the front foot flat, the rear toe
    still and the rear foot keeping its angle (:func:`~.starts.stand_rates`: model 4's
    constraints hold exactly): the states a walk stops from. ``start="stride_stand"`` and
    ``"stride_brake"``: the same two in a walk's double-support geometry (``STRIDE_STAND_*``:
    the rear toe 0.5-0.8 m behind the front toe, its heel up 0.05-0.4 rad, the hip 0.55-0.85 m
    behind the front toe at 2.8-2.92 m: where a walk told to stop enters double support, the
    hip over or behind the rear toe; "stride_brake" also with the hip coming down at 0-0.5 m/s
    and the rear heel rising at 0-3 rad/s, as a walk enters double support).
    ``start="stride_drift"``: the stride-stand posture with the hip moving level at -0.3 to
    0.1 m/s (``STRIDE_DRIFT_HIP_SPEED_RANGE_M_S``), the rear foot keeping its angle: a stop
    after a slow walk, which comes to rest and then drifts backward.
    ``start="nudge"``: the rest
    start's posture in model 1 with the stance leg turning about the ankle at a rate uniform in
    ``NUDGE_RATE_RANGE_RAD_S``
    (-0.6 to 0.2 rad/s: forward, or slowly backward), the swing thigh keeping its direction: the
    states around rest and between rest and walking, for learning to start. A dict of weights
    mixes them, one uniform draw first picking the component (``{"stride": 0.75,
    "midstride": 0.25}``; ``"mixed"`` is ``{"rest": 1, "midstride": 1}``). The
    ``"reference"`` component starts at a recorded state of the reference walk (below;
    ``start="reference"``: every start), drawn first by a draw of its own, the other
    components then as a start of their own. All but "stand", "brake" and their "stride_"
    forms (the rear toe on the ground exactly) add uniform noise in ``[-s, s]``
    (``start={"reset_noise_scale": s}``, 0.01 rad) to q1..q5; the stance toe is at y = 0.
    ``reset(options={"q", "qd", "mode", "stance_side", "root_y"})`` starts from any state in
    the coordinates of docs/conventions.md (validated: points on or above the ground, model
    constraints satisfied; a ``ValueError`` names what is wrong).

    ## Episode End
    ### Termination
    Any out-of-model event of the simulator (``info["termination_reason"]`` names it):
    ``stance_foot_tips_back``, ``stance_heel_down``, ``swing_toe_strike``,
    ``swing_foot_touchdown``, ``body_below_ground``, ``swing_heel_pulls``,
    ``stance_toe_pulls``, ``stance_foot_pulls`` (force events end the episode only with
    ``physics={"strict": True}``, the default), ``step_behind_stance_toe``, ``zeno``,
    ``non_finite`` (the numerical state blew up; the observation is the last finite state),
    and, only if ``termination["fall_hip_height_m"]`` is set, ``fall`` (the hip below that
    height [m] at the end of a period; off by default), and, only if
    ``termination["max_model_time_s"]`` is set, ``model_time`` (one contact phase held longer than
    that [s], by the contact clock: an early termination for learning, as legged-robot RL ends
    episodes on a bad posture), and, only if ``termination["max_first_phase_s"]`` is set,
    ``first_phase_time`` (the first contact phase of a start near rest, model 1 with every joint
    rate at most 0.6 rad/s, held longer than that [s]; ``max_model_time_s`` then applies from
    the first model switch on), and, only if ``termination["max_stop_s"]`` is set (with a
    command), ``stop_time`` (the hip faster than 0.1 m/s in a period more than that [s] after
    the command became zero: walking on through a stop).
    A fall is one of these (a knee or the hip below the ground).
    ### Truncation
    By simulated time: ``termination["time_limit_s"]`` (default 30 s; None: none), the first
    period that ends at or after it (the single and the batched env alike, at any control period,
    whether its periods end early at model switches or not). Gymnasium's ``max_episode_steps`` (a
    limit in control periods) still applies when given.

    ## Arguments
    One keyword per part, each validated once into ``env.settings`` (:mod:`.settings`; printed
    by ``repr(env)``, as data by ``env.settings.as_dict()``); a ``ValueError`` names a wrong
    value, and an old flat keyword (``strict``, ``rsi``, ``phase_obs``...) is refused naming
    its part. ``task`` sets the defaults of every part it names (:data:`~.tasks.TASKS`); a
    part given explicitly overrides the task's (``physics`` and ``start`` dicts key by key,
    ``action`` and ``reward`` dicts key by key onto the task's of the same kind).

    | Parameter | Default (``task="walk"``) | Description (unit) |
    |-----------|---------|--------------------|
    | task | "walk" | "walk", "track" (learning from the reference walk), "command" (a commanded |
    | | | speed, :mod:`.command`) or "paper" (its preset, 20 ms, held torques, rest start) |
    | preset | "default" | "default" (error-controlled RK4_LIMEX), "fixed_step" (RK4_LIMEX, |
    | | | 2.5 ms), "fast" (RK2, 5 ms), "paper" |
    | dt | 0.005 | control period [s] |
    | params | paper_biped() | the robot (``BipedParams``) |
    | physics | {"stop_at_switch": True} | ``SimOptions`` overrides of the preset: "integrator", |
    | | | "substeps" (per period; a preset keeps its longest step at any ``dt``), "impact", |
    | | | "locate_events", "jdot", "strict", "heel_force_includes_foot_weight", "step_tol", |
    | | | "stop_at_switch" (end a period just after a model switch) |
    | action | "torque" | "torque", "pd" (PD targets in [-1, 1]^5, below) or a dict: "kind", |
    | | | "torque_limit_nm" (150: the torque bound [N m]), "out_of_range" ("clip" or |
    | | | "raise"), and the PD mapping's "around" ("fixed" or "reference"), "range" (1.0 |
    | | | [rad]), "pose" (Fig. 2 q1..q5 [rad]), "offset" (zeros [rad], or 4 x 5 per model), |
    | | | "gain_scale" (1.0: Kp x s, Kd x sqrt(s)), "dt" (min(5 ms, dt): the PD law's physics |
    | | | step [s], dividing dt; = dt holds the PD torque) |
    | start | "midstride" | a start's name (Starting State), a dict of component weights, or |
    | | | a dict: "kind" (either), "posture" (``NOMINAL_POSTURE_RAD``: the rest posture [rad]), |
    | | | "reset_noise_scale" (0.01: noise on q1..q5 [rad]); the components "rest", |
    | | | "midstride", "stride", "stand", "brake", "stride_stand", "stride_brake", |
    | | | "stride_drift", "nudge", "reference" (recorded reference states) |
    | reward | "env" | "env" (Rewards), "tracking" (a reference walk's; below), "gait" (the task |
    | | | and the contact clock, no recording; below), "command", or {"kind", "weights", |
    | | | "kernels", "targets", "gated", "first_phase_s", "speed_window_s"}: any term's |
    | | | weight, kernel or target; the cadence target of a start near rest's first |
    | | | contact phase [s]; the command reward's speed averaging time [s] (:mod:`.rewards`) |
    | termination | {} | dict: "fall_hip_height_m" (None: end when the hip is below [m]), |
    | | | "max_model_time_s" (None: end when one model has lasted longer [s]), |
    | | | "max_first_phase_s" (None: end when a start near rest's first model lasts longer [s]), |
    | | | "max_stop_s" (None: end when still moving that long after a zero command [s]), |
    | | | "time_limit_s" (30: truncation by simulated time [s]; None: none) |
    | observation | [] | blocks appended to the 24 entries: "phase" (the contact clock), "gravity" |
    | | | (the direction of gravity in the ground's frame), in the order listed; below |
    | perturbations | None | dict: pushes, model error, slopes, sensor noise, action delay |
    | | | (:mod:`.perturbations`; ``slope_rad``: the ground's slope [rad], a constant or drawn |
    | | | per episode from (lo, hi), gravity turned by it in the ground's frame) |
    | command | None | dict: the commanded forward speed [m/s] (one more observation entry, |
    | | | ``info["command_m_s"]``): "range" (lo, hi), "zero_fraction", "resample_s" (lo, hi) |
    | | | or None (held), "deadband" (commands below it held as 0) [m/s], "ramp_m_s2" (the |
    | | | held command's rate limit; None: off); ``task="command"``: (0, 2), 0.1, (1, 5), 0, |
    | | | None; ``set_command(v)``, ``reset(options={"command": v})``; needs |
    | | | ``reward="command"`` (:mod:`.command`) |
    | reference | None | the reference walk: "midstride", "rest", "own" (each start its own kind's |
    | | | recording) or an npz path (None: the start's own; "own" if mixed) |
    | render_mode | None | "rgb_array" or "human" |

    ``task="paper"`` differs in ``preset`` ("paper"), ``dt`` (0.02), ``physics``
    ({"stop_at_switch": False}) and ``start`` ("rest").

    ## Learning
    The walking task's feasible set is thin: random or zero torques end an episode in its first
    period (``stance_toe_pulls``), so SB3's defaults learn nothing on it. ``task="track"`` sets
    up the task that PPO learns from a random network (docs/sb3.md, a plain-SB3 script).

    ## Tracking task
    Options for learning from a reference walk (:mod:`.tracking`; the default env uses none):
    ``reward="tracking"`` is a DeepMimic-style sum of exponential kernels of the pose, rate, hip
    height and hip speed errors against the reference at the contact clock, plus 1 per completed
    step (``info["reward_<term>"]``); ``start={"reference": f, "midstride": 1 - f}`` starts the
    fraction f of the episodes at recorded reference states; ``action="pd"`` makes the action five
    joint targets, tracked by the PD law ``Kp (target - q) + Kd (rate - q-dot)`` with gains
    ``PD_KP``, ``PD_KD``: the targets hold over the control period and the law, clipped to the
    torque limit, is evaluated at every physics step ``action["dt"]`` inside it, as legged-robot
    envs do (decimation; 20 ms periods apply their targets through four 5 ms PD updates).
    ``info["torque"]`` gives the period's time-mean torque; the control cost is the time mean of
    sum(tau^2). The clock restarts at every model switch; a start follows its own reference's first
    step (rest with "rest", mid-stride with "midstride").

    ``reward="gait"`` (:mod:`.gait`) needs no recorded motion: kernels of the period's hip speed
    against a commanded speed, of the hip height, of the swing ankle's forward speed while the
    swing leg is free (periodic foot speed), and of the time held in the current model (the
    contact clock), plus 1 per completed step and 0 per forward model switch (the ``switch``
    weight: the step's reward paid in quarters); each target is a setting
    (``reward={"kind": "gait", "targets": {"speed": 0.8}}``).

    ## Info
    ``info`` of every step and reset: ``mode`` (1-4), ``stance_side``, ``steps_completed``,
    ``t`` [s], ``hip_y`` and ``root_y`` [m], ``switches`` ((t, from, to) of the period's model
    switches), ``events`` ((t, name, terminal) of each), ``termination_reason`` (None while it
    goes on), ``motor_work_pos_j``, ``motor_work_abs_j`` and ``damping_loss_j`` (since the
    episode's start, summed at every physics step: the motors' positive and absolute work and
    the joint damping's loss [J]), then ``reward_<term>`` of the reward's kind (they add up to
    the reward), and where the settings ask for them ``torque`` (PD actions: the period's
    time-mean torque), ``push_impulse_ns`` and ``push_dv_m_s`` (pushes), ``command_m_s``.

    ## Vector env
    ``gym.make_vec("ConstrainedBiped-v0", num_envs=N, vectorization_mode="vector_entry_point",
    **kwargs)`` takes the same arguments and steps all N rows in one compiled call, row i
    seeded s + i equal to the single env seeded s + i, bit for bit; next-step or same-step
    autoreset (a start drawn below the ground is drawn again, in both envs); ``num_threads``
    numba threads (default 1), ``max_episode_steps`` a limit in periods.

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
      Changed: the PD mapping's settings are one ``action`` dict (``pd_around``,
      ``pd_range``, ``pd_pose``, ``pd_offset``, ``pd_gain_scale`` and ``pd_dt`` became its
      ``around``, ``range``, ``pose``, ``offset``, ``gain_scale`` and ``dt``); ``reward``
      takes a dict of weights and kernels (:data:`~.rewards.REWARD_KINDS`); ``info`` gives the
      terms of the env's own reward kind as ``reward_<term>``, which add up to the reward
      (the tracking reward's were ``track_<term>``, beside walking terms that did not add up);
      the walking weights with another reward kind are refused. Added: ``reference="own"``
      (the default of ``start="mixed"``: each start follows its own kind's recording) and PD
      offsets per model (``action["offset"]`` of 4 x 5). The single and the batched
      env share one core (:mod:`.core`), so their ``info`` keys and values are equal
      (the PD torque and pushes appear in the reset's ``info`` too, zero).
      Added: ``reward="gait"`` and the reward's ``targets`` (the cadence target one
      value or one per model) and ``gated``; ``start="stride"``; ``max_model_time_s``;
      ``restarts``. Removed (no policy or result used them; each refused by name):
      ``restarts`` and ``reference_obs``. Changed: the control period is at least 2 ms, the
      integration steps at least 50 us, ``step_tol`` at least 1e-8 and PD updates at least
      0.5 ms (bounds on the work of an episode); ``info["root_y"]`` added. Added: ``start``
      as a weighted mixture of ``"rest"``, ``"midstride"`` and ``"stride"`` (a dict of
      weights; ``"mixed"`` is ``{"rest": 1, "midstride": 1}``, draw for draw); ground slopes:
      ``BipedParams.slope_rad`` and ``perturbations["slope_rad"]`` (a constant or a range
      drawn per episode), gravity turned by the slope in the ground's frame; the render draws
      the slope. Added: ``task="command"`` (a commanded forward speed, observed, resampled,
      settable with ``set_command`` and ``reset(options={"command": v})``; the ``command``
      option and ``reward="command"``, no recorded motion). Added:
      ``info["motor_work_pos_j"]``, ``["motor_work_abs_j"]`` and ``["damping_loss_j"]``, the
      motors' positive and absolute work and the joint damping's loss since the episode's
      start, summed at every physics step. Changed: one keyword per part (13 and
      ``render_mode``, from 33): the ``SimOptions`` overrides and ``stop_at_switch`` are the
      ``physics`` dict; ``torque_limit_nm`` and ``out_of_range`` keys of ``action``;
      ``posture``, ``reset_noise_scale`` and ``rsi`` keys of ``start``;
      ``fall_hip_height_m``, ``max_model_time_s`` and ``time_limit_s`` the ``termination``
      dict; ``phase_obs=True`` is ``observation=["phase"]``; the "env" reward's weights
      (``forward_reward_weight``...) are ``reward={"weights": {...}}``. Each old keyword is
      refused naming its new place. Changed: the command reward's speed term at a zero
      command pays for standing still in model 4 (both feet down) and half its weight in
      models 1-3 (it was the hip-speed kernel in every model); ``max_model_time_s`` counts a
      contact phase's periods under a speed command only (a restart from standing has the
      whole limit). Added: the command reward's ``effort`` term (weight 0: off); the
      ``"stand"`` start (model 4 at rest, both feet down) and the ``"brake"`` start (the
      same, moving forward at 0-0.8 m/s), and both in a walk's double-support geometry
      (``"stride_stand"``, ``"stride_brake"``); the ``"nudge"`` start (its rates
      -0.6 to 0.2 rad/s: rest inside them). Changed: the
      reference-state
      starts are the start mixture's ``"reference"`` component (``start={"kind": "mixed",
      "rsi": 0.5}`` is ``start={"reference": 0.5, "rest": 0.25, "midstride": 0.25}``, draw
      for draw); ``rsi`` is refused naming it. Added: ``set_start(start)`` in both envs (the
      next episodes' start distribution, for a curriculum over starts). Added: the first
      contact phase of a start near rest (model 1, every joint rate at most 0.6 rad/s) as a
      phase of its own:
      ``termination["max_first_phase_s"]`` (reason ``first_phase_time``) and the gait and
      command rewards' ``first_phase_s`` (its cadence target), for a start from rest whose
      sway before the first step is longer than a walking phase; the gait reward's
      ``switch`` term (a weight per forward model switch, 0 by default; ``info["reward_switch"]``).
      Added: the command reward's ``still`` term (weight 0: off) and
      ``termination["max_stop_s"]`` (reason ``stop_time``).
      Added: the ``"gravity"`` observation block (the direction of gravity in the ground's
      frame: a slope is observed). Added: the ``command`` option's ``deadband`` and
      ``ramp_m_s2`` (both off by default; ``set_command`` returns the held command); the
      ``"stride_drift"`` start (the stride-stand posture drifting at -0.3 to 0.1 m/s).
      Added: the batched env's ``reset(options={"command": v})`` takes one command per row too.
      Added: the command reward's ``speed_window_s`` (off by default): while a speed is
      commanded its ``speed`` term reads the hip speed averaged over that time constant.

    Example:
        >>> import gymnasium as gym
        >>> import biped_constraint_env
        >>> env = gym.make("ConstrainedBiped-v0")
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, info["mode"]
        ((24,), 2)
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 50}

    def __init__(self, render_mode: str | None = None, **kwargs: Any):
        """Create the environment (see the class docstring, Arguments)."""
        self.settings = make_settings(**kwargs)
        s = self.settings
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / s.dt))}
        self.params, self.options, self.dt = s.physics.params, s.physics.options, s.dt
        self.task = s.task
        self.core = EnvCore(s, 1)
        a = s.action.bound
        self.action_space = spaces.Box(-a, a, (N_ACTUATED,), np.float32)
        self.observation_space = self.core.observation_space
        self.observation_names = self.core.observation_names  # entry names, in order
        self._act = self.core.buf.act
        self._rows = np.zeros(1, np.int64)
        limit = s.time_limit_s  # truncation at t >= limit (to round-off); None: never
        self._t_limit = np.inf if limit is None else limit - 1e-9
        self._renderer = None
        self._needs_reset = True  # until a reset succeeds, and again after a termination

    def __repr__(self) -> str:
        """The env with its settings."""
        return f"ConstrainedBipedEnv({self.settings!r})"

    # ---------------------------------------------------------------- state access
    @property
    def state(self) -> SimState:
        """The simulator state (immutable snapshot)."""
        return self.core.sim.get(0)

    def keypoints(self) -> dict[str, np.ndarray]:
        """World positions [m] of toes, heels, ankles, knees and hip of both legs, by name."""
        return keypoints(self.params, self.state)

    # ---------------------------------------------------------------- Gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode (see the class docstring, Starting State)."""
        if seed is not None:
            seed = check_seeds(seed, 1)[0]  # an int >= 0 (numpy's too): not a float or a list
        super().reset(seed=seed)
        self._needs_reset = True  # stays so if this reset is refused
        rngs = self._rngs = [self.np_random]  # this episode's generator (seeded above)
        options, command = split_reset_options(options)
        if options is not None and not (isinstance(options, dict) and not options):
            self.core.set_starts(self._rows, state_from_options(options), rngs, command)
        else:
            self.core.draw_starts(self._rows, rngs, command)
        self.core.buf.observe()
        self.core.clear_period()
        self._needs_reset = False
        info = self.core.info(0)
        if self.render_mode == "human":
            self.render()
        return self.core.first_observation(rngs), info

    def step(self, action):
        """Apply the action for one control period (see the class docstring)."""
        if self._needs_reset:
            raise RuntimeError(
                "step() called before reset() or after the episode ended; call reset()"
            )
        a = action if isinstance(action, np.ndarray) else np.asarray(action)
        if a.shape != (N_ACTUATED,) or a.dtype.kind not in "fiu":
            act = self.settings.action
            validate_action(a, act.bound, act.out_of_range, act.bound_name)
        core, rngs = self.core, self._rngs
        rewards, terminated = core.period(a[None, :], rngs)
        info = core.info(0)
        done = terminated.item(0)
        truncated = not done and info["t"] >= self._t_limit
        self._needs_reset = done or truncated
        if self.render_mode == "human":
            self.render()
        return core.first_observation(rngs), rewards.item(0), done, truncated, info

    def set_start(self, start: str | dict) -> None:
        """Draw the next episodes' starts from ``start``: a start's name or a mixture of weights.

        As the ``start`` setting's ``kind`` (e.g. ``{"rest": 0.5, "stride": 0.5}``); the rest
        posture and reset noise stay, and the episode in progress runs on. A training curriculum
        over starts calls it (``training.ppo``'s ``start_curriculum``). ValueError on an unknown
        start or a ``"reference"`` component the env was not made with.
        """
        self.settings = self.core.set_start_kind(start)

    def set_command(self, v: float) -> float:
        """Set the commanded forward speed [m/s], as a joystick would (``task="command"``).

        It holds until the next reset (no resampling); the next observation carries it.
        Returns the held command: 0 if ``v`` is inside the command's deadband.
        """
        if self.core.commands is None:
            raise ValueError("set_command needs an env with a command (task='command')")
        return float(self.core.commands.set(check_commands(v))[0])

    def render(self):
        """An RGB frame (``rgb_array``) or a window (``human``) of the stick figure."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode")
            return None
        from .render import Renderer

        if self._renderer is None:
            self._renderer = Renderer()
        st = self.state
        slope = self.core.perturb.params[0].slope_rad  # the episode's robot and ground
        frame = self._renderer.frame(
            self.keypoints(), int(st.mode), st.t, st.stance_side, st.steps_completed, slope
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


ENV_ARGUMENTS: tuple[str, ...] = SETTINGS_ARGUMENTS + ("render_mode",)
"""The keyword arguments of ``gym.make("ConstrainedBiped-v0", ...)`` (a misspelt one raises a
ValueError listing these)."""
