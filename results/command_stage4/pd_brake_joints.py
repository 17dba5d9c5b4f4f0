"""Which joint's noise ends the PD hold: the published policy's noise with some joints at 0.5 N m.

pd_brake.py's joint PD hold (:func:`pd_brake.pd_hold`) from 20 brake starts and 20 standing
starts at a zero command, 4 s, with Gaussian torque noise of the published command policy's std
per joint (front ankle, front knee, hip, rear knee, rear ankle: 1.1, 2.6, 3.7, 3.4, 5.0 N m),
some joints lowered to 0.5 N m.

python pd_brake_joints.py -> pd_brake_joints.txt
"""

import numpy as np
from pd_brake import STD, pd_hold

VARIANTS = {
    "every joint the policy's": STD,
    "rear ankle 0.5": np.r_[STD[:4], 0.5],
    "rear knee and ankle 0.5": np.r_[STD[:3], 0.5, 0.5],
    "front ankle 0.5": np.r_[0.5, STD[1:]],
    "both ankles 0.5": np.r_[0.5, STD[1:4], 0.5],
    "hip and rear ankle 0.5": np.r_[STD[:2], 0.5, STD[3], 0.5],
}
for start in ("brake", "stand"):
    for label, sigma in VARIANTS.items():
        held, still, ends = pd_hold(start, sigma)
        print(f"{start}, {label}: held 4 s {held} of 20, still {still}; ended: {ends}", flush=True)
