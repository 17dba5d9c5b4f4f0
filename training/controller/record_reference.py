"""Record the teacher's walks as reference motions (npz) for the tracking task.

    python -m training.controller.record_reference [--seconds 10] [--gait-step 5] [--out DIR]

Runs the teacher (``model:teacher_robust+start_rest``) through the walking task (5 ms periods
ending at each switch, default physics, strict checks, no reset noise) from mid-stride and
from rest (the paper's Fig. 2 posture), and writes ``reference_midstride.npz`` and
``reference_rest.npz`` (:mod:`biped_constraint_env.reference`): every period's state before
its action, on the contact clock (first step from rest or not, model, periods since the model
began). ``--gait-step`` picks the completed-step count whose step is the gait's phase table.
The shipped files are in ``biped_constraint_env/data`` (the default ``--out``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from biped_constraint_env.env import ConstrainedBipedEnv
from biped_constraint_env.observation import OBS_HIP
from biped_constraint_env.reference import DATA_DIR, REFERENCES, save_reference
from training.controller.model_controller import TEACHER, controller_from
from training.plumbing.common import CliParser, command
from training.plumbing.outputs import command_output


def record(
    start: str, seconds: float, teacher: str = TEACHER
) -> tuple[dict[str, np.ndarray], float]:
    """Per period of the teacher's walk from ``start``: its state and contact clock.

    Returns the arrays of :data:`biped_constraint_env.reference.FIELDS` and the period [s].
    """
    env = ConstrainedBipedEnv(start={"kind": start, "reset_noise_scale": 0.0})
    ctl = controller_from(teacher)
    obs, info = env.reset(seed=0)
    ctl.reset()
    rows = {k: [] for k in ("q", "qd", "hip", "mode", "j", "step", "first")}
    j, mode = 0, info["mode"]
    from_rest = start == "rest"
    while info["t"] < seconds:
        st = env.state
        rows["q"].append(st.q.copy())
        rows["qd"].append(st.qd.copy())
        rows["hip"].append(obs[OBS_HIP].copy())
        rows["mode"].append(info["mode"])
        rows["j"].append(j)
        rows["step"].append(info["steps_completed"])
        rows["first"].append(int(from_rest and info["steps_completed"] == 0))
        obs, _, term, trunc, info = env.step(ctl(obs))
        if term or trunc:
            raise RuntimeError(f"the teacher stopped walking: {info['termination_reason']}")
        j = j + 1 if info["mode"] == mode else 0
        mode = info["mode"]
    return {k: np.array(v) for k, v in rows.items()}, env.dt


@command("record_reference")
def main(argv: list[str] | None = None) -> int:
    """Record both references."""
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="simulated time per walk [s]")
    ap.add_argument("--gait-step", type=int, default=5, help="the step of the gait's table")
    ap.add_argument("--out", type=Path, default=DATA_DIR)
    a = ap.parse_args(argv)
    with command_output(a.out, "record_reference") as co:
        for start in REFERENCES:
            arrays, dt = record(start, a.seconds)
            if arrays["step"].max() <= a.gait_step:
                ap.error(f"--gait-step {a.gait_step}: the {start} walk completed only "
                         f"{arrays['step'].max()} steps")  # fmt: skip
            name = f"reference_{start}.npz"
            save_reference(Path(co.dir().where(name)), dt=dt, gait_step=a.gait_step, **arrays)
            print(f"{a.out / name}: {len(arrays['q'])} periods, {arrays['step'].max()} steps")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
