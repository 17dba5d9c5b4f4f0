"""The motors' work and the damping's loss, summed at every physics step, in ``info``.

Checked by hand (one joint driven at a constant torque: its work is the torque times the
angle it turned) and by the energy balance: within one model (no impact), the motors' net
work equals the change of the mechanical energy plus what the damping dissipated.
"""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env import dynamics as dyn

REST = [0.0, -0.1, 0.1, -0.3, -0.4, 0.7]


def _env(**kw):
    env = gym.make("ConstrainedBiped-v0", dt=0.01, physics={"stop_at_switch": True, **kw})
    env.reset(seed=0, options={"q": REST, "mode": 1})
    return env


def _energy(env):
    st = env.unwrapped.state
    ch = env.unwrapped.settings.physics.params.chain(st.stance_side)
    return sum(dyn.energy(ch, st.q, st.qd, st.root_y))


@pytest.mark.parametrize(
    "numerics,rtol", [({}, 1e-3), ({"integrator": "rk4", "substeps": 8}, 1e-5)]
)
def test_work_sums_start_at_zero_and_balance_the_energy_within_a_model(numerics, rtol):
    """Default numerics: the balance closes to the integration's own error (5e-4); with 1.25
    ms RK4 steps to 1e-6 J of 0.12 J (the damping's Simpson rule is not the limit)."""
    env = _env(**numerics)
    info = env.unwrapped.core.info(0)
    assert info["motor_work_pos_j"] == info["motor_work_abs_j"] == info["damping_loss_j"] == 0.0
    e0 = _energy(env)
    tau = np.array([2.0, -3.0, 4.0, 1.5, -1.0])
    for _ in range(10):  # 0.1 s in model 1
        _, _, term, _, info = env.step(tau)
        assert not term and info["mode"] == 1
    pos, ab, damp = info["motor_work_pos_j"], info["motor_work_abs_j"], info["damping_loss_j"]
    net = 2 * pos - ab  # positive minus negative work
    assert 0 < pos <= ab and damp > 0
    assert net == pytest.approx(_energy(env) - e0 + damp, rel=rtol)


def test_one_joints_work_is_its_torque_times_the_angle_it_turned():
    env = _env()
    q0 = env.unwrapped.state.q.copy()
    tau = np.array([0.0, 0.0, 20.0, 0.0, 0.0])  # the swing hip alone, turning one way
    for _ in range(10):
        *_, info = env.step(tau)
    turned = env.unwrapped.state.q[3] - q0[3]
    assert turned > 0.01  # [rad] it did turn forward: all its work positive
    assert info["motor_work_pos_j"] == pytest.approx(20.0 * turned, rel=1e-12)
    assert info["motor_work_abs_j"] == pytest.approx(20.0 * turned, rel=1e-12)


def test_work_is_the_same_in_the_batched_env_and_restarts_with_each_episode():
    kw = {"dt": 0.02}
    single = gym.make("ConstrainedBiped-v0", **kw)
    venv = gym.make_vec("ConstrainedBiped-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        **kw)  # fmt: skip
    venv.reset(seed=4)
    single.reset(seed=4)
    a = np.full(5, 3.0)
    for _ in range(3):
        *_, term, _, info = single.step(a)
        _, _, vterm, _, vinfo = venv.step(np.stack([a, a]))
        assert vinfo["motor_work_pos_j"][0] == info["motor_work_pos_j"]
        assert vinfo["damping_loss_j"][0] == info["damping_loss_j"]
        if term:
            break
    single.reset(seed=5)
    assert single.unwrapped.core.info(0)["motor_work_abs_j"] == 0.0
