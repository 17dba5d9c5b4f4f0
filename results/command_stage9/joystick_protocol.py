"""The command protocol of a run's network with the env's joystick options changed at run time.

python joystick_protocol.py RUN {best,final,checkpoint} DEADBAND [RAMP [N [SEED]]] -> stdout:
the command protocol's rows (start, tracking, stop and restart, sequences;
``command_protocol.run_protocol``) on N episodes (default 20) of seeds SEED+ (default 700000,
the development seeds; as ``evaluate --episodes N --seed SEED``) in the run's env with
``command={..., "deadband": DEADBAND [m/s], "ramp_m_s2": RAMP [m/s^2]}`` (RAMP omitted or 0: no
ramp). The network is unchanged; only the commands it is given are.
"""

import sys

import torch

from biped_constraint_env.settings import with_keys
from training.plumbing import command_protocol as cp
from training.ppo.policy_io import load_policy, policy_batch_actor

torch.set_num_threads(1)
policy, norm, cfg, state = load_policy(sys.argv[1], sys.argv[2])
joystick = {"deadband": float(sys.argv[3])}
if len(sys.argv) > 4 and float(sys.argv[4]) > 0:
    joystick["ramp_m_s2"] = float(sys.argv[4])
kw = with_keys(cfg.env_kwargs(), "command", **joystick)
first = int(sys.argv[6]) if len(sys.argv) > 6 else 700000
seeds = list(range(first, first + (int(sys.argv[5]) if len(sys.argv) > 5 else 20)))
rows = cp.run_protocol(policy_batch_actor(policy, norm, cfg), kw, seeds, cfg.env_id)
print(f"# {sys.argv[2]}/ at {state['num_timesteps']} env steps; command option {kw['command']}")
print(cp.markdown(rows), end="")
