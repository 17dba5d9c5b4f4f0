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


def test_the_energy_figure_reads_command_rows_and_walkers_and_refuses_an_old_evaluation(tmp_path):
    import json

    from training.evaluation import energy_figure

    cmd = {"results": [{}], "command_protocol": [
        {"row": "start"},
        {"row": "track 0.3 m/s", "command_m_s": 0.3, "cost_of_transport_mean": 2.5,
         "damping_share_mean": 0.9},
        {"row": "track 1.0 m/s", "command_m_s": 1.0, "cost_of_transport_mean": 1.5,
         "damping_share_mean": 0.8}]}  # fmt: skip
    walker = {
        "results": [
            {
                "speed_mean_m_s": 1.2,
                "cost_of_transport_mean": 2.0,
                "cost_of_transport_abs_mean": 2.4,
                "damping_share_mean": 0.7,
            }
        ]
    }
    old = {"results": [{"speed_mean_m_s": 1.2, "cost_of_transport_mean": 2.0}]}
    for name, d in (("cmd", cmd), ("walker", walker), ("old", old)):
        (tmp_path / f"{name}.json").write_text(json.dumps(d))
    assert [p["speed_m_s"] for p in energy_figure.points(tmp_path / "cmd.json")] == [0.3, 1.0]
    (w,) = energy_figure.points(tmp_path / "walker.json")
    assert (w["speed_m_s"], w["cot"], w["damping_share"]) == (1.2, 2.0, 0.7)
    with pytest.raises(SystemExit, match="evaluate the policy again"):
        energy_figure.points(tmp_path / "old.json")
    out = tmp_path / "out"
    args = ["--evaluations", str(tmp_path / "cmd.json"), str(tmp_path / "walker.json"),
            "--labels", "command", "walker", "--out", str(out)]  # fmt: skip
    assert energy_figure.main(args) == 0
    assert (out / "energy.png").is_file() and "| walker | 1.20 | 2.00 | 70% |" in (
        out / "energy.md").read_text()  # fmt: skip
