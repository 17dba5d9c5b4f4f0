"""The soft-contact MuJoCo twin (biped_constraint_env.twin): its chain, its state in the paper's
terms, its contact estimate. Skipped without MuJoCo (the bench extra)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("mujoco")

from biped_constraint_env.model import paper_biped  # noqa: E402
from biped_constraint_env.simulator import SimOptions, SimState, integrate_mode  # noqa: E402
from biped_constraint_env.twin import Twin, TwinOptions, twin_mjcf  # noqa: E402


@pytest.mark.parametrize("slope", [0.0, 0.05])
def test_the_twins_chain_with_foot_a_welded_is_model_1_to_round_off(slope):
    """Foot A fixed flat, no contact, RK4 at 0.1 ms: the twin's q1..q5 over 1 s equal the
    constraint model's model 1 (its own RK4) with torques held."""
    import mujoco

    params = paper_biped(slope_rad=slope)
    model = mujoco.MjModel.from_xml_string(
        twin_mjcf(params, TwinOptions(timestep_s=1e-4), weld=True)
    )
    data = mujoco.MjData(model)
    q0 = np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])
    tau = np.array([10.0, 120.0, 35.0, 80.0, 0.0])
    data.qpos[:] = q0[1:]
    data.ctrl[:] = tau
    st = SimState(0.0, 1, 0, q0, np.zeros(6))
    opts = SimOptions(integrator="rk4")
    worst = 0.0
    for k in range(10_000):
        mujoco.mj_step(model, data)
        st = integrate_mode(params, st, tau, 1e-4, opts)
        if (k + 1) % 1000 == 0:
            worst = max(worst, np.abs(data.qpos - st.q[1:]).max())
    assert worst < 1e-9


@pytest.mark.parametrize("side", [0, 1])
def test_a_state_set_in_the_papers_terms_reads_back(side):
    rng = np.random.default_rng(side)
    twin = Twin(paper_biped())
    for _ in range(5):
        q, qd = rng.uniform(-1.0, 1.0, 6), rng.uniform(-2.0, 2.0, 6)
        twin.set_state(q, qd, side, 0.37, 2)
        q2, qd2, root = twin.paper_state()
        assert np.abs(q2 - q).max() < 1e-12 and np.abs(qd2 - qd).max() < 1e-12
        assert root == pytest.approx(0.37, abs=1e-12)
        assert (twin.mode, twin.side, twin.steps) == (2, side, 0)


def test_a_state_read_in_the_other_numbering_is_the_renumbered_one():
    """The same physical state read with leg B standing is the constraint model's renumbering
    (paper eq. 25-29, ``nb_renumber``)."""
    from biped_constraint_env.hybrid import nb_renumber

    params = paper_biped()
    rng = np.random.default_rng(3)
    q, qd = rng.uniform(-1.0, 1.0, 6), rng.uniform(-2.0, 2.0, 6)
    twin = Twin(params)
    twin.set_state(q, qd, 0, 0.2, 1)
    twin.side = 1
    q_b, qd_b, root_b = twin.paper_state()
    ch0, ch1 = params.chain(0).packed, params.chain(1).packed
    want_q, want_qd, want_root = nb_renumber(ch0, ch1, params.chain(0).packed_scalars, q, qd, 0.2)
    assert np.abs(q_b - want_q).max() < 1e-12 and np.abs(qd_b - want_qd).max() < 1e-12
    assert root_b == pytest.approx(want_root, abs=1e-12)


def test_standing_at_rest_the_estimate_holds_model_1_and_counts_no_step():
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401

    env = gym.make("ConstrainedBiped-v0", task="command", start="rest")
    env.reset(seed=0)
    st, params = env.unwrapped.state, env.unwrapped.params
    twin = Twin(params)
    twin.set_state(st.q, st.qd, st.stance_side, st.root_y, st.mode)
    twin.step(np.zeros(5), 0.1)
    assert (twin.mode, twin.side, twin.steps) == (st.mode, st.stance_side, 0)
    # the stance foot carries the weight, split between its heel and toe
    weight = params.total_mass_kg * params.gravity_mps2
    toe, heel, point = twin.paper_forces()
    assert point == 0.0 and toe > 0 and heel > 0
    assert toe + heel == pytest.approx(weight, rel=0.3)  # moving: not a static split
    assert not twin.fallen()


def test_the_toe_pivots_damping_is_the_papers_and_a_weld_has_no_ground():
    params = dataclasses.replace(paper_biped())
    twin = Twin(params)
    assert twin.toe_damping == params.links[0].damping_nms_per_rad
    assert 'type="plane"' in twin_mjcf(params) and "base_y" not in twin_mjcf(params, weld=True)


def test_a_policy_runs_in_the_twin_from_the_constraint_envs_start():
    """The driver's episode: the constraint env's start for the seed, the policy's own env
    options, its observation computed from the twin's state as the env computes it."""
    from training.evaluation.sim_to_sim import twin_episode
    from training.ppo.policy_io import (
        ObsNormalizer,
        open_policy,
        policy_batch_actor,
        published_snapshot,
    )

    src = "policies/ppo_command_stop_50hz"
    policy, norm, cfg, _, _ = open_policy(src, published_snapshot(src)[0])
    seen = []

    def act(obs):
        seen.append(obs.copy())
        return policy_batch_actor(policy, ObsNormalizer(norm), cfg)(obs)

    ep = twin_episode(act, {**cfg.env_kwargs(), "start": "rest"}, 700_000, 2.0, command=1.0)
    assert ep["end"] == "time_limit" and ep["t_s"] == pytest.approx(2.0)
    assert len(seen) == 100 and seen[0].shape == (1, cfg.obs_dim())
    names = cfg.obs_names()
    assert {o[0, names.index("command_m_s")] for o in seen} == {1.0}
    assert ep["distance_m"] > 0.5  # it walks off
