"""The model-1 chain (stance foot fixed flat) in MuJoCo, generated from our parameters.

The MJCF is built in the q = 0 posture (legs vertical, both feet flat) with hinge joints
about +x, so that MuJoCo's qpos equals our (q1..q5) and positive rotation is counter-clockwise
in the y-z plane. Masses, COM offsets, transverse inertias, joint damping and gravity are ours;
contacts are disabled (the stance foot is the world). Used only by benchmarks and tests.
"""

from __future__ import annotations

import numpy as np

from biped_constraint_env.model import (
    COL_COM,
    COL_DAMPING,
    COL_INERTIA,
    COL_MASS,
    SC_GRAVITY,
    SC_GRAVITY_T,
    ChainModel,
)

INTEGRATOR_TIMESTEP_S = 1e-4


def make_mjcf(chain: ChainModel, timestep: float = INTEGRATOR_TIMESTEP_S) -> str:
    """MJCF text of links 1..5 hanging from the fixed stance ankle."""
    ch = chain.packed
    g, gt = chain.packed_scalars[SC_GRAVITY], chain.packed_scalars[SC_GRAVITY_T]
    lengths = [link.length_m for link in chain.links]
    # direction of each link at q = 0 along z: stance shank and thigh up, swing thigh and shank down
    up = {1: 1.0, 2: 1.0, 3: -1.0, 4: -1.0}

    def inertial(i, com_z):
        ixx = ch[i, COL_INERTIA]
        return (
            f'<inertial pos="0 0 {com_z:.17g}" mass="{ch[i, COL_MASS]:.17g}" '
            f'diaginertia="{ixx:.17g} {ixx:.17g} {ixx:.17g}"/>'
        )

    def joint(i):
        return (
            f'<joint name="j{i}" type="hinge" axis="1 0 0" damping="{ch[i, COL_DAMPING]:.17g}" '
            f'armature="0" frictionloss="0" limited="false"/>'
        )

    ankle_y = -0.5 * lengths[0]
    body = (
        f'<body name="foot_b" pos="0 0 {up[4] * lengths[4]:.17g}">{joint(5)}'
        f"{inertial(5, 0.0)}</body>"
    )
    for i in (4, 3, 2, 1):
        if i == 1:
            pos = f"0 {ankle_y:.17g} 0"
        elif i == 3:
            pos = f"0 0 {lengths[2]:.17g}"
        else:
            pos = f"0 0 {up[i - 1] * lengths[i - 1]:.17g}"
        body = (
            f'<body name="link{i}" pos="{pos}">{joint(i)}'
            f"{inertial(i, up[i] * ch[i, COL_COM])}{body}</body>"
        )
    motors = "".join(f'<motor joint="j{i}" gear="1" ctrllimited="false"/>' for i in range(1, 6))
    return (
        '<mujoco model="biped_model1">'
        f'<option timestep="{timestep:.17g}" gravity="0 {-gt:.17g} {-g:.17g}" '
        'integrator="RK4">'
        '<flag contact="disable"/></option>'
        f"<worldbody>{body}</worldbody><actuator>{motors}</actuator></mujoco>"
    )


def build(chain: ChainModel, timestep: float = INTEGRATOR_TIMESTEP_S):
    """(model, data) of MuJoCo for the model-1 chain."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(make_mjcf(chain, timestep))
    return model, mujoco.MjData(model)


def mass_matrix(model, data, q5: np.ndarray) -> np.ndarray:
    """(5, 5) MuJoCo mass matrix at q1..q5."""
    import mujoco

    data.qpos[:] = q5
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    try:  # MuJoCo >= 3.3: mj_fullM(m, d, dst)
        mujoco.mj_fullM(model, data, M)
    except TypeError:  # older: mj_fullM(m, dst, qM)
        mujoco.mj_fullM(model, M, data.qM)
    return M


def simulate(model, data, q5: np.ndarray, tau5: np.ndarray, t_end: float, sample_every: int):
    """Integrate from rest with constant torques; returns (times, qpos samples)."""
    import mujoco

    mujoco.mj_resetData(model, data)
    data.qpos[:] = q5
    data.ctrl[:] = tau5
    n = int(round(t_end / model.opt.timestep))
    ts, qs = [0.0], [data.qpos.copy()]
    for k in range(1, n + 1):
        mujoco.mj_step(model, data)
        if k % sample_every == 0:
            ts.append(data.time)
            qs.append(data.qpos.copy())
    return np.array(ts), np.array(qs)
