"""The same planar chain built in Pinocchio (optional benchmark/validation dependency).

Each link i gets a revolute-X joint (rotation about +x, counter-clockwise in the y-z plane);
joint i's frame is placed in link i-1's frame by a rotation of offset_i about x and a
translation of next_{i-1} along the parent's local y axis (the parent link's direction).
Link inertia: mass m, COM at com_i along local y, rotational inertia I about x (the in-plane
axis); the out-of-plane inertias do not enter planar motion.
"""

from __future__ import annotations

import numpy as np

from biped_constraint_env.model import (
    COL_ANGLE,
    COL_COM,
    COL_INERTIA,
    COL_MASS,
    COL_NEXT,
    SC_GRAVITY,
    SC_GRAVITY_T,
    ChainModel,
)


def build(chain: ChainModel):
    """(model, data) of Pinocchio for ``chain`` (root joint 0 at the world origin)."""
    import pinocchio as pin

    ch = chain.packed
    model = pin.Model()
    g, gt = chain.packed_scalars[SC_GRAVITY], chain.packed_scalars[SC_GRAVITY_T]
    model.gravity.linear = np.array([0.0, -gt, -g])  # turned by the ground's slope
    parent = 0
    for i in range(6):
        rot = pin.utils.rotate("x", ch[i, COL_ANGLE])
        trans = np.zeros(3) if i == 0 else np.array([0.0, ch[i - 1, COL_NEXT], 0.0])
        placement = pin.SE3(rot, trans)
        jid = model.addJoint(parent, pin.JointModelRX(), placement, f"joint{i}")
        inertia = np.diag([ch[i, COL_INERTIA], ch[i, COL_INERTIA], ch[i, COL_INERTIA]])
        model.appendBodyToJoint(
            jid,
            pin.Inertia(ch[i, COL_MASS], np.array([0.0, ch[i, COL_COM], 0.0]), inertia),
            pin.SE3.Identity(),
        )
        parent = jid
    return model, model.createData()


def point_jacobian_z(model, data, q, link: int, s: float) -> np.ndarray:
    """(6,) world z-row of the Jacobian of the point at offset s along link (Pinocchio route)."""
    import pinocchio as pin

    jid = link + 1
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J6 = pin.getJointJacobian(model, data, jid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    oMi = data.oMi[jid]
    r = oMi.rotation @ np.array([0.0, s, 0.0])
    # velocity of the point = v_joint + w x r
    Jv = J6[:3] - np.cross(r, J6[3:].T).T
    return Jv[2]
