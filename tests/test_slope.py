"""A constant ground slope: gravity turned by the slope in the ground's frame.

The contact stays the paper's plane z = 0 (of the ground's frame), so a slope costs no new
contact geometry; checked against independent routes: the gravity torques against the
gradient of the potential m (g cos(a) z + g sin(a) y) by the complex step (the Lagrangian
route of test_dynamics); the chain turned by the slope on flat ground under plain gravity
(the root's angle is absolute), which must give the same torques and, turned back, the same
ground force; and the energy balance with the turned gravity's potential.
"""

import dataclasses
import math

import numpy as np
import pytest
from test_dynamics import CS, RTOL_INDEPENDENT, _coms

from biped_constraint_env import dynamics as dyn
from biped_constraint_env.model import COL_MASS, PAPER_LINKS, paper_biped
from biped_constraint_env.simulator import SimOptions, SimState, integrate_mode

SLOPES = (-0.09, 0.05, 0.3)  # [rad]


def _potential_gradient(ch, q, g, slope):
    grad = np.zeros(6)
    for k in range(6):
        qc = q.astype(complex)
        qc[k] += 1j * CS
        c, _ = _coms(ch, qc)
        v = g * ch[:, COL_MASS] * (math.cos(slope) * c[:, 1] + math.sin(slope) * c[:, 0])
        grad[k] = v.sum().imag / CS
    return grad


@pytest.mark.parametrize("slope", SLOPES)
def test_gravity_torques_are_the_turned_potentials_gradient(slope):
    ch = paper_biped(slope_rad=slope).chain(0)
    for seed in range(3):
        q = np.random.default_rng(seed).normal(size=6)
        got = dyn.rnea(ch, q, np.zeros(6), np.zeros(6))
        ref = _potential_gradient(ch.packed, q, 9.8, slope)
        assert np.abs(got - ref).max() <= RTOL_INDEPENDENT * np.abs(ref).max()


@pytest.mark.parametrize("slope", SLOPES)
def test_slope_equals_the_chain_turned_on_flat_ground(slope):
    sloped = paper_biped(slope_rad=slope).chain(0)
    flat = paper_biped().chain(0)
    rng = np.random.default_rng(7)
    for _ in range(3):
        q, qd, qdd = rng.normal(size=6), 2 * rng.normal(size=6), 50 * rng.normal(size=6)
        turned = q.copy()
        turned[0] += slope
        got = dyn.rnea(sloped, q, qd, qdd)
        ref = dyn.rnea(flat, turned, qd, qdd)
        assert np.abs(got - ref).max() <= 1e-12 * np.abs(ref).max()
        f_slope = dyn.rnea_full(sloped, q, qd, qdd).joint_force[0]
        f_flat = dyn.rnea_full(flat, turned, qd, qdd).joint_force[0]
        c, s = math.cos(slope), math.sin(slope)  # the ground's frame -> the world's
        world = np.array([c * f_slope[0] - s * f_slope[1], s * f_slope[0] + c * f_slope[1]])
        assert np.abs(world - f_flat).max() <= 1e-12 * np.abs(f_flat).max()


@pytest.mark.parametrize("mode", [1, 2])
@pytest.mark.parametrize("slope", (-0.09, 0.09))
def test_energy_conserved_on_a_slope_without_damping(mode, slope):
    links = tuple(dataclasses.replace(k, damping_nms_per_rad=0.0) for k in PAPER_LINKS)
    p = paper_biped(links=links, slope_rad=slope)
    ch = p.chain(0)
    q = np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])
    qd = np.array([0.0, 0.5, -0.3, 0.8, -0.5, 0.2])
    if mode == 2:
        q[0], qd[0] = -0.05, -0.3
    st = SimState(0.0, mode, 0, q, qd, root_y=0.7)
    e0 = sum(dyn.energy(ch, st.q, st.qd, st.root_y))
    flat0 = sum(dyn.energy(paper_biped(links=links).chain(0), st.q, st.qd))
    assert abs(e0 - flat0) > 0.5  # [J] the slope's potential differs from the flat one's
    opts = SimOptions(integrator="rk4")
    for _ in range(500):
        st = integrate_mode(p, st, np.zeros(5), 2e-4, opts)
    assert abs(sum(dyn.energy(ch, st.q, st.qd, st.root_y)) - e0) <= 1e-6 * abs(e0)


def test_flat_ground_is_the_paper_bit_for_bit():
    chs, scs = paper_biped(slope_rad=0.0).packed
    assert scs[:, 0].tolist() == [9.8, 9.8] and scs[:, 7].tolist() == [0.0, 0.0]
    with pytest.raises(ValueError, match="slope_rad"):
        paper_biped(slope_rad=0.5)


def _walk(slope, n=60, **kw):
    """The env from the rest start with zero torques: its info after ``n`` periods."""
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401

    env = gym.make("ConstrainedBiped-v0", perturbations={"slope_rad": slope}, start="rest", **kw)
    env.reset(seed=0)
    for _ in range(n):
        *_, term, trunc, info = env.step(np.zeros(5))
        if term or trunc:
            break
    return env, info


def test_env_slope_setting_draws_per_episode_the_same_in_both_envs():
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401

    kw = {"perturbations": {"slope_rad": (-0.09, 0.09)}, "dt": 0.02}
    single = gym.make("ConstrainedBiped-v0", **kw)
    slopes = []
    for s in range(6):
        single.reset(seed=s)
        slopes.append(single.unwrapped.core.perturb.params[0].slope_rad)
    assert len(set(slopes)) == 6 and all(-0.09 <= a <= 0.09 for a in slopes)
    venv = gym.make_vec("ConstrainedBiped-v0", num_envs=6, vectorization_mode="vector_entry_point",
                        **kw)  # fmt: skip
    venv.reset(seed=0)
    rows = [p.slope_rad for p in venv.unwrapped.core.perturb.params]
    assert rows == slopes
    with pytest.raises(ValueError, match="slope_rad"):
        gym.make("ConstrainedBiped-v0", perturbations={"slope_rad": 0.5})


def test_a_downhill_start_falls_forward_faster_and_the_render_draws_the_slope():
    _, flat = _walk(0.0, n=20)
    env, down = _walk(-0.2, n=20, render_mode="rgb_array")
    assert down["t"] == flat["t"] > 0.05
    assert down["hip_y"] > flat["hip_y"] + 0.01  # gravity pulls it forward
    frame = env.render()
    dark = np.argwhere((frame == 90).all(axis=2))  # the ground line's pixels
    left, right = dark[dark[:, 1] < 100], dark[dark[:, 1] > frame.shape[1] - 100]
    assert left[:, 0].mean() < right[:, 0].mean() - 20  # downhill: the ground falls to the right


def test_gravity_observation_gives_each_rows_slope_the_same_in_both_envs():
    """``observation=["gravity"]``: (-sin a, -cos a) of each row's own slope, after the base
    entries and before the command; on flat ground (0, -1). Without it the rest start's
    observation on a slope equals the flat one (a slope shows only in the motion)."""
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401
    from biped_constraint_env.observation import OBS_DIM

    G = slice(OBS_DIM, OBS_DIM + 2)  # the gravity block's entries

    kw = {"perturbations": {"slope_rad": (-0.09, 0.09)}, "observation": ["gravity", "phase"],
          "task": "command"}  # fmt: skip
    single = gym.make("ConstrainedBiped-v0", **kw)
    assert single.observation_space.shape == (OBS_DIM + 5,)
    rows = []
    for s in range(4):
        obs, _ = single.reset(seed=s, options={"command": 0.7})
        a = single.unwrapped.core.perturb.params[0].slope_rad
        assert obs[G] == pytest.approx([-math.sin(a), -math.cos(a)], abs=1e-15)
        assert obs[-1] == 0.7  # the command's entry stays last
        obs, *_ = single.step(np.zeros(5))
        assert obs[G] == pytest.approx([-math.sin(a), -math.cos(a)], abs=1e-15)
        rows.append(obs[G])
    assert len({round(float(r[0]), 12) for r in rows}) == 4  # drawn per episode
    venv = gym.make_vec("ConstrainedBiped-v0", num_envs=4, vectorization_mode="vector_entry_point",
                        **kw)  # fmt: skip
    obs, _ = venv.reset(seed=0)
    first, _ = single.reset(seed=0)
    np.testing.assert_array_equal(obs[0], first)
    slopes = np.array([p.slope_rad for p in venv.unwrapped.core.perturb.params])
    want = np.stack([-np.sin(slopes), -np.cos(slopes)], 1)
    np.testing.assert_allclose(obs[:, G], want, atol=1e-15)
    flat, _ = gym.make("ConstrainedBiped-v0", observation=["gravity"]).reset(seed=0)
    assert flat[OBS_DIM:].tolist() == [0.0, -1.0]
    plain = [gym.make("ConstrainedBiped-v0", start="rest", perturbations={"slope_rad": a})
             .reset(seed=0)[0] for a in (0.0, 0.0873)]  # fmt: skip
    np.testing.assert_array_equal(plain[0], plain[1])
    with pytest.raises(ValueError, match="observation block"):
        gym.make("ConstrainedBiped-v0", observation=["gravity", "slope"])
