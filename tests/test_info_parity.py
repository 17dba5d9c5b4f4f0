"""``info`` has the same keys and values in the single and the batched env, for every task
option (the batched env adds Gymnasium's ``_key`` masks), and for every reward kind the reward
is the sum of the ``reward_<term>`` entries."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from training.controller.model_controller import controller_from

OPTIONS = [
    {},
    {"reward": {"weights": {"step": 2.0, "ctrl": 0.3, "alive": 0.2}}},
    {
        "reward": {"kind": "tracking", "weights": {"pose": 0.7}, "kernels": {"hip_speed": 2.0}},
        "action": "pd",
    },
    {"task": "paper"},
    {"observation": ["phase"], "start": "mixed"},
    {"reward": "tracking", "start": {"reference": 0.5, "midstride": 0.5}, "observation": ["phase"]},
    {"action": {"kind": "pd", "offset": [0.2, 0, 0, 0, 0]}},
    {"action": {"kind": "pd", "around": "reference"}, "reward": "tracking", "dt": 0.01},
    {"perturbations": {"push_impulse_ns": -0.3, "push_at_s": 0.1, "obs_noise": (1e-3, 1e-2)}},
    {"reward": {"kind": "gait", "targets": {"speed": 0.8}, "weights": {"step": 2.0}}},
    {"reward": "gait", "action": {"kind": "pd", "offset": [0.2, 0, 0, 0, 0]}, "dt": 0.02},
    {"reward": "gait", "termination": {"max_model_time_s": 0.1}},
    {
        "reward": {"kind": "gait", "gated": True, "first_phase_s": 0.3, "weights": {"switch": 1}},
        "termination": {"max_model_time_s": 0.05, "max_first_phase_s": 0.15},
        "start": {"rest": 0.5, "nudge": 0.25, "midstride": 0.25},
    },
    {
        "reward": {"kind": "gait", "gated": True, "targets": {"cadence": [0.3, 0.1, 0.1, 0.1]}},
        "action": {"kind": "pd", "offset": [0.2, 0, 0, 0, 0]},
        "dt": 0.02,
    },
]


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(a, b)
    return a == b


@pytest.mark.parametrize("kw", OPTIONS, ids=lambda kw: ",".join(kw) or "default")
def test_info_keys_and_values_agree(kw):
    n = 2
    venv = gym.make_vec("ConstrainedBiped-v0", n, vectorization_mode="vector_entry_point", **kw)
    envs = [gym.make("ConstrainedBiped-v0", **kw) for _ in range(n)]
    _, vinfo = venv.reset(seed=5)
    infos = [e.reset(seed=5 + i)[1] for i, e in enumerate(envs)]
    for i, info in enumerate(infos):  # the resets' too
        assert {k for k in vinfo if not k.startswith("_")} == set(info)
        assert all(_same(info[key], vinfo[key][i]) for key in info)
    teacher = controller_from("model:teacher_robust")
    pd = "action" in kw
    live = [True] * n
    obs = [None] * n
    vobs = None
    for k in range(60):
        if pd:
            a = np.zeros((n, 5))
        else:
            a = teacher(vobs[:, :24]) if vobs is not None else np.tile([5.0, -20, 0, 0, 0], (n, 1))
        vobs, vrew, vterm, _, vinfo = venv.step(a)
        for i, e in enumerate(envs):
            if not live[i]:
                continue
            obs[i], rew, term, _, info = e.step(a[i])
            assert rew == vrew[i]
            terms = [info[k] for k in info if k.startswith("reward_")]
            kind = e.unwrapped.settings.reward
            assert len(terms) == len(kind.terms) >= 5
            assert rew == pytest.approx(sum(terms), abs=1e-12)
            keys = set(info)
            assert keys <= set(vinfo), keys - set(vinfo)
            assert {k for k in vinfo if not k.startswith("_")} == keys
            for key in keys:
                assert _same(info[key], vinfo[key][i]), (key, info[key], vinfo[key][i])
                assert vinfo[f"_{key}"][i]
            live[i] = not term
        if not any(live):
            break
