"""Pushes through the constrained impulse map, model randomisation, sensor noise, action delay:
identical in the single and the batched env, seeded, and nothing drawn by default."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.dynamics import nb_mass_matrix
from biped_constraint_env.kinematics import nb_point_jacobian
from biped_constraint_env.model import SC_HEEL5, SC_TOE5, paper_biped
from biped_constraint_env.perturbations import HIP_LINK, hip_impulse
from training.controller.model_controller import controller_from

ALL = {
    "push_impulse_ns": (-0.6, 0.3),
    "push_interval_s": (0.2, 0.4),
    "mass_scale": (0.9, 1.1),
    "damping_scale": (0.8, 1.2),
    "friction_ratio": (0.4, 0.6),
    "obs_noise": (0.001, 0.01),
    "action_delay": 1,
}


def _rollout_pair(kw: dict, periods: int = 400, n: int = 3, seed: int = 10):
    """Step the batched env and n single envs with the teacher's actions; compare everything."""
    venv = gym.make_vec("ConstrainedBiped-v0", n, vectorization_mode="vector_entry_point", **kw)
    envs = [gym.make("ConstrainedBiped-v0", **kw) for _ in range(n)]
    vo, _ = venv.reset(seed=seed)
    for i, e in enumerate(envs):
        assert np.array_equal(e.reset(seed=seed + i)[0], vo[i])
    ctrl = controller_from("model:teacher_robust")
    live = np.ones(n, bool)
    pushes = 0
    for _ in range(periods):
        a = ctrl(vo)
        vo, vr, vt, _, vi = venv.step(a)
        for i, e in enumerate(envs):
            if not live[i]:
                continue
            o, r, t, _, info = e.step(a[i])
            assert np.array_equal(o, vo[i]) and r == vr[i] and t == vt[i]
            for key in ("push_dv_m_s", "push_impulse_ns"):
                if key in info:
                    assert info[key] == vi[key][i]
                    pushes += key == "push_dv_m_s" and info[key] != 0.0
            live[i] = not t
        if not live.any():
            break
    return pushes


@pytest.mark.parametrize(
    "pert",
    [
        ALL,
        {"push_impulse_ns": (-0.4, -0.2), "push_interval_s": (0.3, 0.5)},
        {"mass_scale": (0.8, 1.2), "friction_ratio": (0.3, 0.7)},
        {"obs_noise": (0.002, 0.02)},
        {"action_delay": 1},
    ],
)
def test_perturbations_single_equals_batched(pert):
    _rollout_pair({"perturbations": pert})


def test_pushes_happen_and_are_reported_alike():
    assert _rollout_pair({"perturbations": {"push_impulse_ns": -0.3, "push_at_s": 0.2}}) == 3


def test_nothing_is_drawn_by_default():
    """The default env and an env with every option off give the same episodes."""
    a = gym.make("ConstrainedBiped-v0")
    b = gym.make("ConstrainedBiped-v0", perturbations={})
    oa, _ = a.reset(seed=3)
    ob, _ = b.reset(seed=3)
    assert np.array_equal(oa, ob)
    assert a.unwrapped.np_random.random() == b.unwrapped.np_random.random()


def test_model_randomisation_is_per_row_and_seeded():
    kw = {"perturbations": {"mass_scale": (0.8, 1.2), "friction_ratio": (0.3, 0.7)}}
    venv = gym.make_vec("ConstrainedBiped-v0", 4, vectorization_mode="vector_entry_point", **kw)
    venv.reset(seed=0)
    chs = venv.unwrapped.core.buf.chs.copy()
    assert len({chs[i, 0, 1, 0] for i in range(4)}) == 4  # four different shank masses
    venv.reset(seed=0)
    assert np.array_equal(venv.unwrapped.core.buf.chs, chs)  # the same draws again
    nominal = gym.make_vec("ConstrainedBiped-v0", 2, vectorization_mode="vector_entry_point")
    nominal.reset(seed=0)
    assert np.all(nominal.unwrapped.core.buf.chs == nominal.unwrapped.core.buf.chs[0])


@pytest.mark.parametrize("mode", [1, 2, 3, 4])
def test_the_push_keeps_the_models_contacts_and_is_an_impulse(mode):
    """C dq = 0 for the model's contacts, and M dq - J_hip^T P lies in the span of C^T."""
    params = paper_biped()
    q = np.array([0.05, -0.3, 0.4, -0.2, -0.5, 0.6])
    P = np.array([0.7, 0.0])
    dq = hip_impulse(params, mode, 0, q, P)
    ch = params.chain(0)
    pk, sc = ch.packed, ch.packed_scalars
    rows = []
    if mode in (1, 4):
        rows.append(np.eye(6)[0])
    if mode in (3, 4):
        j = nb_point_jacobian(pk, q, 5, float(sc[SC_HEEL5 if mode == 3 else SC_TOE5]))
        rows += [j[0], j[1]]
    jac = nb_point_jacobian(pk, q, HIP_LINK, 0.0)
    residual = nb_mass_matrix(pk, q) @ dq - (jac[0] * P[0] + jac[1] * P[1])
    if rows:
        C = np.array(rows)
        np.testing.assert_allclose(C @ dq, 0.0, atol=1e-10)
        lam, *_ = np.linalg.lstsq(C.T, residual, rcond=None)  # the contact impulses
        np.testing.assert_allclose(C.T @ lam, residual, atol=1e-9)
    else:
        np.testing.assert_allclose(residual, 0.0, atol=1e-9)
    assert (jac[0] @ dq) * P[0] > 0  # the hip moves the way it is pushed


@pytest.mark.parametrize(
    ("pert", "match"),
    [
        ({"push_impulse_ns": 1.0}, "exactly one of"),
        ({"push_interval_s": (1, 2)}, "need push_impulse_ns"),
        ({"mass_scale": (1.2, 0.8)}, "low <= high"),
        ({"action_delay": 2}, "action_delay"),
        ({"surprise": 1}, "unknown option"),
        ({"obs_noise": (-1.0, 0.0)}, "obs_noise"),
    ],
)
def test_bad_perturbations_are_refused(pert, match):
    with pytest.raises(ValueError, match=match):
        gym.make("ConstrainedBiped-v0", perturbations=pert)
