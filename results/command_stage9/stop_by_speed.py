"""The command protocol's stop row episode by episode, by the speed walked before the stop.

python stop_by_speed.py RUN {best,final,checkpoint} [N [DEADBAND RAMP]] -> stdout: per episode
of the protocol's stop row (seeds 700000+, development; N, default 40; the walk commands drawn
as ``command_protocol.stop_rows`` draws them), the walk command, the hip speed at the stop
command (5 s), whether it stood (at rest within 3 s, held 5 s), when it was first at rest for
0.5 s after the stop command, how and when the episode ended; then the stands per band of walk
command. DEADBAND [m/s] and RAMP [m/s^2] (0: none) set the env's joystick options at run time,
as ``joystick_protocol.py``'s; omitted, the run's own env.
"""

import sys

import numpy as np
import torch

from biped_constraint_env.settings import with_keys
from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
n = int(sys.argv[3]) if len(sys.argv) > 3 else 40
seeds = list(range(700000, 700000 + n))
walk = np.random.default_rng(seeds[0]).uniform(0.3, 2.0, n)  # the draw of stop_rows
kw = cfg.env_kwargs()
if len(sys.argv) > 5:
    ramp = {"ramp_m_s2": float(sys.argv[5])} if float(sys.argv[5]) > 0 else {}
    kw = with_keys(kw, "command", deadband=float(sys.argv[4]), **ramp)
REST_S = 0.5  # "at rest": every period's mean hip speed below the stand speed for this long [s]
restart_at = cp.STOP_AT_S + cp.STOP_WITHIN_S + cp.HOLD_S


def command(t, k):
    """Walk, then 0 from 5 s, then 1.0 m/s (as the protocol's stop row)."""
    return np.where(t < cp.STOP_AT_S, walk, np.where(t < restart_at, 0.0, cp.START_COMMAND_M_S))


eps = cp.run_commanded(policy_batch_actor(policy, norm, cfg), kw, seeds, command,
                       restart_at + 10.0, cfg.env_id)  # fmt: skip
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; command option {kw.get('command')}")
stood = []
for k in np.argsort(walk):
    ep = eps[k]
    t, v = cp.period_speeds(ep)
    ok = cp.stands(t, v, cp.STOP_AT_S, ep["t"][-1])[0]
    stood.append((walk[k], ok))
    calm = [
        a
        for a in t[(t > cp.STOP_AT_S) & (t <= restart_at)]
        if np.all(np.abs(v[(t >= a) & (t <= a + REST_S)]) < cp.STAND_SPEED_M_S)
    ]
    rest = f"at rest {REST_S} s from {calm[0]:.2f} s" if calm else f"never at rest {REST_S} s"
    print(f"{ep['seed']} walk {walk[k]:.2f} m/s, {np.interp(cp.STOP_AT_S, t, v):.2f} m/s at the "
          f"stop; stood {int(ok)}; {rest}; {ep['end']} at {ep['t'][-1]:.2f} s")  # fmt: skip
w, ok = np.array([s[0] for s in stood]), np.array([s[1] for s in stood])
for lo, hi in ((0.3, 0.8), (0.8, 1.3), (1.3, 2.0)):
    m = (w >= lo) & (w < hi + (hi == 2.0))
    print(f"walk {lo}-{hi} m/s: stood {ok[m].sum()} of {m.sum()}")
