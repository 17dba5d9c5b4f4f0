"""The command task: a commanded forward speed, observed, resampled, settable, and its reward."""

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.command import CommandReward, Commands, CommandSettings
from biped_constraint_env.rewards import reward_settings
from biped_constraint_env.settings import make_settings, with_keys

POLICY = Path(__file__).resolve().parents[1] / "policies" / "ppo_command_50hz"

REST = [0.0, -0.1, 0.1, -0.3, -0.4, 0.7]
KW = {"task": "command", "command": {"range": (0.0, 2.0), "zero_fraction": 0.2,
                                     "resample_s": (0.1, 0.3)}}  # fmt: skip


def _vec(n, **kw):
    return gym.make_vec("ConstrainedBiped-v0", num_envs=n, vectorization_mode="vector_entry_point",
                        **kw)  # fmt: skip


def test_command_is_observed_resampled_from_the_rows_generator_the_same_in_both_envs():
    single = gym.make("ConstrainedBiped-v0", **KW)
    venv = _vec(3, **KW)
    obs_v, info_v = venv.reset(seed=10)
    seen = []
    for row in range(3):
        obs, info = single.reset(seed=10 + row)
        assert obs[-1] == info["command_m_s"] == obs_v[row, -1] == info_v["command_m_s"][row]
        cmds = [info["command_m_s"]]
        for _ in range(40):  # 0.8 s: several resamplings
            obs, _, term, trunc, info = single.step(np.zeros(5))
            cmds.append(obs[-1])
            if term or trunc:
                break
        seen.append(cmds)
    assert all(0.0 <= c <= 2.0 for cmds in seen for c in cmds)
    assert any(len(set(c)) > 1 for c in seen)  # resampled within the episode
    obs2, _ = venv.reset(seed=10)
    assert np.array_equal(obs2, obs_v)  # seeded: the same commands again


def test_zero_commands_come_with_the_zero_fraction():
    c = Commands(2000, CommandSettings(range=(0.5, 1.5), zero_fraction=0.25, resample_s=None))
    rngs = [np.random.default_rng(s) for s in range(2000)]
    c.start(np.arange(2000), rngs, np.zeros(2000))
    zero = c.v == 0.0
    assert 0.21 < zero.mean() < 0.29 and np.all((c.v[~zero] >= 0.5) & (c.v[~zero] <= 1.5))
    assert np.all(np.isinf(c.next_t))  # resample_s=None: one command per episode


def test_the_deadband_holds_small_commands_as_zero_drawn_set_and_given_in_both_envs():
    c = Commands(2000, CommandSettings(range=(0.0, 1.0), zero_fraction=0.0, resample_s=None,
                                       deadband=0.2))  # fmt: skip
    rngs = [np.random.default_rng(s) for s in range(2000)]
    c.start(np.arange(2000), rngs, np.zeros(2000))
    assert not np.any((c.v > 0.0) & (c.v < 0.2)) and 0.15 < (c.v == 0.0).mean() < 0.25
    assert c.v.max() > 0.9  # only the band is zeroed
    kw = {**KW, "command": {**KW["command"], "deadband": 0.2}}
    env = gym.make("ConstrainedBiped-v0", **kw)
    obs, info = env.reset(seed=0, options={"command": 0.15})
    assert obs[-1] == 0.0 == info["command_m_s"]
    assert env.unwrapped.set_command(-0.19) == 0.0
    assert env.step(np.zeros(5))[0][-1] == 0.0
    assert env.unwrapped.set_command(0.2) == 0.2  # the band's edge is a command
    assert env.step(np.zeros(5))[0][-1] == 0.2
    venv = _vec(2, **kw)
    venv.reset(seed=0)
    assert venv.unwrapped.set_command([0.1, 0.3]).tolist() == [0.0, 0.3]
    assert venv.step(np.zeros((2, 5)))[0][:, -1].tolist() == [0.0, 0.3]
    # drawn commands: the single and the batched env hold the same, none inside the band
    single = gym.make("ConstrainedBiped-v0", **kw)
    obs_v, _ = venv.reset(seed=40)
    for row in range(2):
        assert single.reset(seed=40 + row)[0][-1] == obs_v[row, -1]
    seen = []
    for seed in range(3):
        single.reset(seed=seed)
        for _ in range(30):  # 0.6 s: several resamplings
            obs, _, term, trunc, _ = single.step(np.zeros(5))
            seen.append(obs[-1])
            if term or trunc:
                break
    assert len(set(seen)) > 3 and not any(0.0 < abs(v) < 0.2 for v in seen)
    with pytest.raises(ValueError, match="deadband"):
        gym.make("ConstrainedBiped-v0", **{**KW, "command": {"deadband": -0.1}})


def test_the_ramp_moves_the_held_command_at_its_rate_and_the_deadband_zeroes_its_tail():
    s = CommandSettings(range=(2.0, 2.0), zero_fraction=0.0, resample_s=None, deadband=0.25,
                        ramp_m_s2=1.5)  # fmt: skip
    c = Commands(2, s)
    rows = np.arange(2)
    c.start(rows, [np.random.default_rng(0)] * 2, np.zeros(2))
    assert c.v.tolist() == [2.0, 2.0]  # an episode starts at its command: no ramp
    assert c.set([0.0, 1.0]).tolist() == [2.0, 2.0]  # held until the periods ramp them
    held, t = [], 0.0
    for _ in range(100):
        t += 0.02
        c.before_period(np.full(2, t), None, rows)
        held.append(c.v.copy())
    held = np.array(held)
    # 2.0 - 1.5 * 0.02 k until it passes the band's edge (0.25 m/s: after 58 periods), then 0
    k = np.arange(1, 101)
    ramp = np.maximum(2.0 - 1.5 * 0.02 * k, 0.0)
    assert held[:, 0] == pytest.approx(np.where(ramp < 0.25, 0.0, ramp), abs=1e-12)
    assert held[:, 1] == pytest.approx(np.maximum(ramp, 1.0), abs=1e-12)
    assert (held[:, 0] == 0.0).sum() == 100 - 58 and held[-1, 1] == 1.0  # exactly reached
    # the env: set_command ramps the observed command in both envs alike
    kw = {"task": "command", "command": {"range": (0.0, 2.0), "zero_fraction": 0.0,
                                         "resample_s": None, "ramp_m_s2": 1.0}}  # fmt: skip
    env = gym.make("ConstrainedBiped-v0", **kw)
    env.reset(seed=0, options={"command": 1.0})
    env.unwrapped.set_command(0.0)
    single = [env.step(np.zeros(5))[0][-1] for _ in range(3)]
    venv = _vec(2, **kw)
    venv.reset(seed=0, options={"command": 1.0})
    venv.unwrapped.set_command(0.0)
    batched = [venv.step(np.zeros((2, 5)))[0][:, -1] for _ in range(3)]
    assert single == pytest.approx([1.0, 0.98, 0.96], abs=1e-9)  # the value at each start
    assert np.allclose(batched, np.array(single)[:, None], atol=1e-12)
    with pytest.raises(ValueError, match="ramp_m_s2"):
        gym.make("ConstrainedBiped-v0", **{**kw, "command": {"ramp_m_s2": 0.0}})


def test_a_user_sets_the_command_as_a_joystick_and_it_holds():
    kw = {**KW, "command": {**KW["command"], "resample_s": (0.05, 0.1)}}
    env = gym.make("ConstrainedBiped-v0", **kw)
    obs, info = env.reset(seed=0, options={"command": 1.5})
    assert obs[-1] == 1.5 == info["command_m_s"]
    for _ in range(10):  # 0.2 s: past every resampling time of drawn commands
        obs, *_ = env.step(np.zeros(5))
    assert obs[-1] == 1.5
    env.unwrapped.set_command(0.0)
    assert env.step(np.zeros(5))[0][-1] == 0.0
    venv = _vec(2, **KW)
    venv.reset(seed=0)
    venv.unwrapped.set_command([0.3, 1.2])
    assert venv.step(np.zeros((2, 5)))[0][:, -1].tolist() == [0.3, 1.2]
    with pytest.raises(ValueError, match="command"):
        env.unwrapped.set_command(float("nan"))
    with pytest.raises(ValueError, match="needs an env with a command"):
        gym.make("ConstrainedBiped-v0").unwrapped.set_command(1.0)
    with pytest.raises(ValueError, match="go together"):
        gym.make("ConstrainedBiped-v0", reward="command")


def test_the_batched_reset_takes_one_command_per_row_as_the_single_env_takes_each():
    kw = {**KW, "command": {**KW["command"], "ramp_m_s2": 1.0, "deadband": 0.2}}
    venv = _vec(3, **kw)
    given = [0.0, 0.7, 1.9]
    obs_v, info_v = venv.reset(seed=5, options={"command": np.array(given)})
    assert obs_v[:, -1].tolist() == given == info_v["command_m_s"].tolist()  # no ramp at a start
    single = gym.make("ConstrainedBiped-v0", **kw)
    steps_v = [venv.step(np.zeros((3, 5)))[0] for _ in range(15)]  # past the resampling times
    for row, v in enumerate(given):
        obs, _ = single.reset(seed=5 + row, options={"command": v})
        assert np.array_equal(obs, obs_v[row])  # the same start, drawn from the row's seed
        for k in range(15):
            obs = single.step(np.zeros(5))[0]
            assert np.array_equal(obs, steps_v[k][row]) and obs[-1] == v  # held: none drawn
    assert venv.reset(seed=5, options={"command": 0.7})[0][:, -1].tolist() == [0.7] * 3
    assert venv.reset(seed=5, options={"command": np.float64(0.7)})[0][:, -1].tolist() == [0.7] * 3
    assert venv.reset(seed=5, options={"command": np.array(0.7)})[0][:, -1].tolist() == [0.7] * 3
    assert single.reset(seed=5, options={"command": np.array(0.7)})[0][-1] == 0.7
    # with a given start state too: each row its command, the same state
    obs_q, _ = venv.reset(seed=5, options={"command": given, "q": REST})
    assert obs_q[:, -1].tolist() == given and np.array_equal(obs_q[0, :-1], obs_q[2, :-1])
    with pytest.raises(ValueError, match="one per row"):
        venv.reset(seed=5, options={"command": [0.5, 1.0]})
    with pytest.raises(ValueError, match="command"):
        venv.reset(seed=5, options={"command": [0.5, float("nan"), 1.0]})
    with pytest.raises(ValueError, match="command"):
        single.reset(seed=5, options={"command": [0.5]})  # the single env: one value


def test_command_reward_follows_the_command_and_pays_standing_at_zero():
    s = make_settings(task="command")
    r = CommandReward(s.reward, s.dt, 2)
    args = dict(hip_z=np.full(2, 2.95), swing_vy=np.ones(2), modes=np.array([4, 4]),
                model_time_s=np.array([5.0, 5.0]), steps=np.zeros(2),
                alive=np.ones(2, bool), tau_sq=np.zeros(2))  # fmt: skip
    # hip still in model 4, a contact phase held 5 s: at a zero command all but the steps pay
    # in full
    out = r.terms(np.zeros(2), command=np.array([0.0, 1.0]), **args)
    assert out[0, :4].tolist() == pytest.approx([0.4, 0.2, 0.2, 0.2])
    assert out[1, 0] == 0.0 and out[1, 3] == pytest.approx(0.0, abs=1e-12)  # gated off
    # at a zero command: drifting in model 4 pays less; models 1-3 half the speed weight
    out = r.terms(np.array([0.5, 0.0]) * s.dt, command=np.zeros(2), **args)
    assert out[0, 0] == pytest.approx(0.4 * np.exp(-4 * 0.25)) and out[1, 0] == pytest.approx(0.4)
    for m in (1, 2, 3):
        out = r.terms(np.zeros(2), command=np.zeros(2), **dict(args, modes=np.array([m, m])))
        assert out[:, 0].tolist() == pytest.approx([0.2, 0.2])
    # walking at the command pays the speed term in full, another speed less
    moving = dict(args, model_time_s=np.array([0.1, 0.1]))
    out = r.terms(np.array([1.0, 0.6]) * s.dt, command=np.array([1.0, 1.0]), **moving)
    assert out[0, 0] == pytest.approx(0.4) and out[1, 0] == pytest.approx(0.4 * np.exp(-4 * 0.16))
    out = r.terms(np.zeros(2), command=np.array([0.0, 2.0]), **dict(moving, steps=np.ones(2)))
    assert out[:, 4].tolist() == [0.0, 10.0]  # steps pay nothing at a zero command
    assert np.allclose(out[:, -1], out[:, :-1].sum(axis=1))
    assert not out[:, 5].any()  # the effort term is off by default
    on = CommandReward(make_settings(task="command", reward={"kind": "command",
                                                             "weights": {"effort": 0.2}}).reward,
                       s.dt, 2)  # fmt: skip
    out = on.terms(np.zeros(2), command=np.ones(2), **dict(args, tau_sq=np.array([0.0, 75.0**2])))
    assert out[:, 5].tolist() == pytest.approx([0.2, 0.2 * np.exp(-2.0 * 0.25)])
    # the still term: off by default; on, at a zero command it pays slowness in every model
    assert not r.terms(np.zeros(2), command=np.zeros(2), **args)[:, 6].any()
    still = CommandReward(make_settings(task="command", reward={"kind": "command",
                                                                "weights": {"still": 0.4}}).reward,
                          s.dt, 2)  # fmt: skip
    for m in (1, 2, 3, 4):
        out = still.terms(np.array([0.5, 0.5]) * s.dt, command=np.array([0.0, 1.0]),
                          **dict(args, modes=np.array([m, m])))  # fmt: skip
        assert out[:, 6].tolist() == pytest.approx([0.4 * np.exp(-4 * 0.25), 0.0])
        assert np.allclose(out[:, -1], out[:, :-1].sum(axis=1))


def test_the_speed_window_averages_each_rows_periods_from_its_start():
    """``speed_window_s``: while moving is commanded the speed term reads the rows' exponential
    average of their periods' mean speeds, begun at each start; rows not stepped keep theirs;
    a zero command still reads the period's own speed."""
    s = make_settings(task="command", reward={"kind": "command", "speed_window_s": 0.5,
                                              "kernels": {"speed": 16.0}})  # fmt: skip
    assert s.reward.speed_window_s == 0.5 and reward_settings(s.reward.as_dict()) == s.reward
    r = CommandReward(s.reward, s.dt, 3)
    a = 1.0 - np.exp(-s.dt / 0.5)
    v = [np.array([0.2, 0.4, 1.0]), np.array([0.6, 0.0, 3.0]), np.array([1.0, 1.0, 1.0])]
    assert np.allclose(r.average_speed(v[0] * s.dt), v[0])  # begun at the first period's speed
    avg = r.average_speed(v[1] * s.dt, skip=np.array([2]))  # row 2 not stepped: kept
    want = np.array([0.2 + a * 0.4, 0.4 - a * 0.4, 1.0])
    assert np.allclose(avg, want)
    r.start(np.array([1]))  # row 1 starts again
    avg = r.average_speed(v[2] * s.dt)
    want = np.array([want[0] + a * (1.0 - want[0]), 1.0, 1.0])
    assert np.allclose(avg, want)
    args = dict(hip_z=np.full(3, 2.95), swing_vy=np.ones(3), modes=np.full(3, 4),
                model_time_s=np.full(3, 0.05), steps=np.zeros(3), alive=np.ones(3, bool),
                tau_sq=np.zeros(3))  # fmt: skip
    out = r.terms(v[2] * s.dt, command=np.array([0.5, 0.0, 1.0]), avg_speed=avg, **args)
    assert out[:, 0] == pytest.approx([0.4 * np.exp(-16 * (want[0] - 0.5) ** 2),
                                       0.4 * np.exp(-16 * 1.0), 0.4])  # fmt: skip
    assert (
        CommandReward(make_settings(task="command").reward, s.dt, 3).average_speed(np.zeros(3))
        is None
    )  # off by default
    for bad, match in (
        ({"kind": "gait", "speed_window_s": 1.0}, "'command' reward"),
        ({"kind": "command", "speed_window_s": 0.0}, "speed_window_s"),
        ({"kind": "command", "speed_window_s": "1"}, "speed_window_s"),
    ):
        with pytest.raises(ValueError, match=match):
            make_settings(task="command", reward=bad)


def test_the_speed_window_is_paid_alike_in_both_envs_and_begins_again_at_an_autoreset():
    """The committed command policy from rest at 1.0 m/s with a 1 s window: the single and the
    batched env pay the same speed term, the average of the hip's periods (from ``hip_y``) by
    hand; a row the batched env starts again pays its first period's own speed."""
    from training.ppo.policy_io import load_policy, policy_batch_actor

    policy, norm, cfg, _ = load_policy(POLICY)
    walker = policy_batch_actor(policy, norm, cfg)
    reward = {
        "kind": "command",
        "speed_window_s": 1.0,
        "kernels": {"speed": 16.0},
        "gated": False,
    }  # the speed term alone (not times the cadence kernel)
    kw = {**cfg.env_kwargs(), "start": "rest", "reward": reward,
          "command": {"resample_s": None, "zero_fraction": 0.0}}  # fmt: skip
    single = gym.make(cfg.env_id, **kw)
    venv = _vec(1, **kw)
    obs, info = single.reset(seed=700001, options={"command": 1.0})
    obs_v, _ = venv.reset(seed=700001, options={"command": 1.0})
    dt, k = single.unwrapped.settings.dt, 16.0
    avg, y = None, info["hip_y"]
    for _ in range(60):
        a = walker(obs[None, :])[0]
        obs, _, term, trunc, info = single.step(a)
        _, _, _, _, info_v = venv.step(a[None, :])
        v = (info["hip_y"] - y) / dt
        y = info["hip_y"]
        avg = v if avg is None else avg + (1.0 - np.exp(-dt / 1.0)) * (v - avg)
        assert info["reward_speed"] == info_v["reward_speed"][0]
        assert info["reward_speed"] == pytest.approx(0.4 * np.exp(-k * (avg - 1.0) ** 2), rel=1e-9)
        assert not (term or trunc)
    # a zero action from rest falls; the batched row starts again and its average with it,
    # in either autoreset mode (NEXT_STEP: a period that skips the row, then its first)
    from gymnasium.vector import AutoresetMode

    for mode in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
        venv = _vec(1, autoreset_mode=mode, **kw)
        venv.reset(seed=3, options={"command": 1.0})
        for _ in range(400):
            _, _, term, trunc, info_v = venv.step(np.zeros((1, 5)))
            if term[0] or trunc[0]:
                break
        assert term[0] and not trunc[0]
        if mode == AutoresetMode.NEXT_STEP:
            venv.step(np.zeros((1, 5)))  # the autoreset period: the row starts again
        y = venv.unwrapped.core.hip[0, 0]
        _, _, _, _, info_v = venv.step(np.zeros((1, 5)))
        v = (info_v["hip_y"][0] - y) / dt
        cmd = info_v["command_m_s"][0]
        assert cmd > 0.0 and info_v["steps_completed"][0] == 0  # drawn, never zero here
        assert info_v["reward_speed"][0] == pytest.approx(0.4 * np.exp(-k * (v - cmd) ** 2),
                                                          rel=1e-9)  # fmt: skip


def test_the_hold_term_pays_a_whole_period_in_double_support_at_a_zero_command():
    s = make_settings(task="command")
    args = dict(hip_z=np.full(4, 2.95), swing_vy=np.ones(4), model_time_s=np.full(4, 0.04),
                steps=np.zeros(4), alive=np.ones(4, bool), tau_sq=np.zeros(4))  # fmt: skip
    off = CommandReward(s.reward, s.dt, 4)
    col = [t.name for t in off.specs].index("hold")
    # rows: a whole period in model 4 at 1.5 m/s; one that entered model 4; one that left it
    # (ends in model 1); a whole period in model 4 while a speed is commanded
    period = dict(args, modes=np.array([4, 4, 1, 4]), switches=np.array([0.0, 1.0, 1.0, 0.0]))
    cmd = np.array([0.0, 0.0, 0.0, 1.0])
    assert not off.terms(np.full(4, 1.5) * s.dt, command=cmd, **period)[:, col].any()  # off
    on = CommandReward(make_settings(task="command", reward={
        "kind": "command", "weights": {"hold": 0.5}}).reward, s.dt, 4)  # fmt: skip
    out = on.terms(np.full(4, 1.5) * s.dt, command=cmd, **period)
    assert out[:, col].tolist() == pytest.approx([0.5 * np.exp(-0.25 * 2.25), 0.0, 0.0, 0.0])
    assert out[0, 0] < 0.2 * np.exp(-0.25 * 2.25)  # where the speed term pays less than walking
    assert np.allclose(out[:, -1], out[:, :-1].sum(axis=1))
    dead = on.terms(np.full(4, 1.5) * s.dt, command=cmd, **dict(period, alive=np.zeros(4, bool)))
    assert not dead[:, col].any()  # a period ended by an event earns only its steps
    with pytest.raises(ValueError, match="switches"):
        on.terms(np.zeros(4), command=cmd, **dict(period, switches=None))


def test_the_hold_term_in_both_envs_is_paid_where_a_period_stays_in_model_4():
    """From a standing start at a zero command, a joint PD hold of the start's posture keeps
    model 4, then the committed command policy walks off: the single and the batched env pay
    the same hold term, exactly in the periods that begin and end in model 4 with no switch."""
    from training.ppo.policy_io import load_policy, policy_batch_actor

    policy, norm, cfg, _ = load_policy(POLICY)
    walker = policy_batch_actor(policy, norm, cfg)
    kw = {**cfg.env_kwargs(), "start": "stand",
          "reward": {"kind": "command", "weights": {"hold": 1.0}}}  # fmt: skip
    single = gym.make(cfg.env_id, **kw)
    venv = _vec(1, **kw)
    obs, info = single.reset(seed=700000, options={"command": 0.0})
    obs_v, _ = venv.reset(seed=700000, options={"command": 0.0})
    assert np.array_equal(obs, obs_v[0]) and info["mode"] == 4
    q0 = single.unwrapped.state.q[1:].copy()
    paid = []
    for k in range(20):
        st = single.unwrapped.state
        a = -100.0 * (st.q[1:] - q0) - 10.0 * st.qd[1:] if k < 10 else walker(obs[None, :])[0]
        mode0 = info["mode"]
        obs, _, term, trunc, info = single.step(a)
        obs_v, _, _, _, info_v = venv.step(a[None, :])
        assert info["reward_hold"] == info_v["reward_hold"][0]
        whole = mode0 == 4 and info["mode"] == 4 and not info["switches"]
        assert (info["reward_hold"] > 0) == (whole and not term)
        paid.append(info["reward_hold"] > 0)
        if term or trunc:
            break
    assert all(paid[:10]) and not any(paid[10:]) and len(paid) > 10  # held, then walked off


def test_the_load_term_pays_the_old_toes_force_at_a_model_4_periods_start():
    s = make_settings(task="command")
    on = CommandReward(make_settings(task="command", reward={
        "kind": "command", "weights": {"load": 2.0}}).reward, s.dt, 4)  # fmt: skip
    col = [t.name for t in on.specs].index("load")
    args = dict(hip_z=np.full(4, 2.95), swing_vy=np.ones(4), model_time_s=np.full(4, 0.04),
                steps=np.zeros(4), alive=np.ones(4, bool), tau_sq=np.zeros(4),
                modes=np.array([1, 4, 4, 1]), switches=np.zeros(4))  # fmt: skip
    # rows: pulling 300 N, pressing 50 N, not in model 4 (NaN), pulling under a speed command
    fn = np.array([-300.0, 50.0, np.nan, -300.0])
    out = on.terms(np.zeros(4), command=np.array([0.0, 0.0, 0.0, 1.0]), contact_fn=fn, **args)
    assert out[:, col].tolist() == pytest.approx([2.0 * np.exp(-0.1 * 9.0), 2.0, 0.0, 0.0])
    assert np.allclose(out[:, -1], out[:, :-1].sum(axis=1))
    off = CommandReward(s.reward, s.dt, 4)
    assert not off.terms(np.zeros(4), command=np.zeros(4), **args)[:, col].any()
    with pytest.raises(ValueError, match="contact forces"):
        on.terms(np.zeros(4), command=np.zeros(4), **args)
    margin = CommandReward(make_settings(task="command", reward={
        "kind": "command", "weights": {"load": 2.0}, "targets": {"load": 100.0}}).reward,
        s.dt, 4)  # fmt: skip
    out = margin.terms(np.zeros(4), command=np.zeros(4), contact_fn=fn, **args)
    assert out[:, col].tolist() == pytest.approx(
        [2.0 * np.exp(-0.1 * 16.0), 2.0 * np.exp(-0.1 * 0.25), 0.0, 2.0 * np.exp(-0.1 * 16.0)]
    )


def test_the_load_terms_force_is_the_simulators_and_alike_in_both_envs():
    """From a standing start at a zero command: a PD hold, then the committed policy walks off.
    The force the term reads at each model-4 period's start equals the simulator's own solve
    (``simulator.evaluate``) at that state and torque, and both envs pay the same."""
    from biped_constraint_env.hybrid import FC_CONTACT
    from biped_constraint_env.simulator import evaluate
    from training.ppo.policy_io import load_policy, policy_batch_actor

    policy, norm, cfg, _ = load_policy(POLICY)
    walker = policy_batch_actor(policy, norm, cfg)
    w = {"load": 1.0}
    kw = {**cfg.env_kwargs(), "start": "stand", "reward": {"kind": "command", "weights": w}}
    single = gym.make(cfg.env_id, **kw)
    venv = _vec(1, **kw)
    obs, info = single.reset(seed=700001, options={"command": 0.0})
    obs_v, _ = venv.reset(seed=700001, options={"command": 0.0})
    u = single.unwrapped
    q0 = u.state.q[1:].copy()
    kinds = set()
    for k in range(12):
        st = u.state
        a = -100.0 * (st.q[1:] - q0) - 10.0 * st.qd[1:] if k < 6 else walker(obs[None, :])[0]
        expected = evaluate(u.params, st, np.clip(a, -150, 150), u.options)[1][FC_CONTACT]
        obs, _, term, trunc, info = single.step(a)
        obs_v, _, _, _, info_v = venv.step(a[None, :])
        assert info["reward_load"] == info_v["reward_load"][0]
        if int(st.mode) == 4 and not term:
            kern = np.exp(-0.1 * (min(0.0, expected) / 100.0) ** 2)
            assert info["reward_load"] == pytest.approx(kern, rel=1e-9)
            kinds.add(bool(expected > 0))
        else:
            assert info["reward_load"] == 0.0
        if term or trunc:
            break
    assert kinds == {True, False}  # held (pressing), then lifted by the walker (pulling)
    pd = gym.make("ConstrainedBiped-v0", task="command", action="pd",
                  reward={"kind": "command", "weights": w})  # fmt: skip
    pd.reset(seed=0, options={"command": 0.0})
    with pytest.raises(ValueError, match="torque actions"):
        pd.step(np.zeros(5))


def test_a_held_contact_phase_ends_the_episode_only_while_moving_is_commanded():
    kw = {**KW, "termination": {"max_model_time_s": 0.1}}
    ended = {}
    for c in (0.0, 1.0):
        env = gym.make("ConstrainedBiped-v0", **kw)
        env.reset(seed=0, options={"command": c, "q": REST})
        *_, term, _, info = env.step(np.zeros(5))
        for _ in range(6):  # 0.14 s: past the limit, still in model 1
            if term:
                break
            *_, term, _, info = env.step(np.zeros(5))
        ended[c] = info["termination_reason"]
    assert ended == {0.0: None, 1.0: "model_time"}


def test_a_restart_from_standing_gets_the_whole_limit_from_the_new_command():
    kw = {**KW, "termination": {"max_model_time_s": 0.1}}
    env = gym.make("ConstrainedBiped-v0", **kw)
    env.reset(seed=0, options={"command": 0.0, "q": REST})
    for _ in range(10):  # 0.2 s standing in model 1 at a zero command: past the limit
        *_, term, _, info = env.step(np.zeros(5))
        assert not term and info["mode"] == 1
    env.unwrapped.set_command(1.0)
    reasons = []
    for _ in range(8):
        *_, term, _, info = env.step(np.zeros(5))
        reasons.append(info["termination_reason"])
        if term:
            break
    # the limit counts from the command: 5 periods (0.1 s) pass, the 6th ends the episode
    assert reasons == [None] * 5 + ["model_time"], reasons


def test_protocol_measures_stride_speed_and_sets_commands_between_periods(monkeypatch):
    from training.plumbing import command_protocol as cp

    # a synthetic walk at 1.2 m/s with a step every 0.4 s: stride speed error 0.2 at 1.0 m/s
    t = np.arange(0, 10.0, 0.02)
    ep = {"t": list(t), "hip_y": list(1.2 * t), "step_t_s": list(np.arange(0.4, 10.0, 0.4))}
    errs = cp.stride_errors(ep, 1.0)
    assert errs and np.allclose(errs, 0.2)
    seen = []

    def act(obs):
        seen.append(obs[:, -1].copy())  # the command entry the network sees
        return np.zeros((len(obs), 5))

    eps = cp.run_commanded(act, {"task": "command"}, [0, 1],
                           lambda tt, k: np.where(tt < 0.1, 0.5, 1.5), 0.3)  # fmt: skip
    assert seen[0].tolist() == [0.5, 0.5] and all(e["command"][0] == 0.5 for e in eps)
    assert any(s.tolist() == [1.5, 1.5] for s in seen)  # changed when the time came
    assert all(len(e["t"]) == len(e["hip_y"]) for e in eps)
    # with the joystick's ramp too, an episode starts at its command, not at the reset's draw
    seen.clear()
    cp.run_commanded(act, {"task": "command", "command": {"ramp_m_s2": 1.0}}, [0, 1],
                     lambda tt, k: np.full(len(tt), 0.7), 0.1)  # fmt: skip
    assert seen and all(s.tolist() == [0.7, 0.7] for s in seen)
    # the robustness rows at 1.0 m/s: each condition's perturbation reaches the env
    kw = []
    walked = [{"steps_completed": 20, "end": "time_limit"}]
    monkeypatch.setattr(cp, "run_commanded", lambda a, k, *_: kw.append(k) or walked)
    rows = cp.model_rows(act, {"task": "command"}, [0], "ConstrainedBiped-v0")
    rows += cp.slope_rows(act, {"task": "command"}, [0], "ConstrainedBiped-v0")
    assert [k["perturbations"] for k in kw[:3]] == [
        {"mass_scale": (0.9, 1.1)},
        {"friction_ratio": (0.4, 0.6)},
        {"obs_noise": (0.005, 0.05)},
    ]
    assert kw[3]["perturbations"] == {"slope_rad": pytest.approx(np.radians(-5.0))}
    n = len(cp.SLOPES_DEG)  # each slope from the policy's start, then from mid-stride
    assert len(kw) == 3 + 2 * n and "start" not in kw[3] and kw[3 + n]["start"] == "midstride"
    assert kw[3 + n]["perturbations"] == kw[3]["perturbations"]
    assert rows[3]["row"] == "slope -5.0 deg, 1.0 m/s"
    assert rows[3 + n]["row"] == "slope -5.0 deg from mid-stride, 1.0 m/s"
    assert [r["row"] for r in rows[:3]] == [
        "link masses ±10%, 1.0 m/s",
        "K 0.4-0.6, 1.0 m/s",
        "sensor noise 0.005 rad, 0.05 rad/s, 1.0 m/s",
    ]
    assert all(r["success"]["rate"] == 1.0 for r in rows)


def test_with_keys_sets_joystick_options_inside_the_command_and_keeps_the_rest():
    kw = {"task": "command", "command": {"range": (0.0, 1.0)}}
    out = with_keys(kw, "command", deadband=0.2, ramp_m_s2=1.0)
    assert out["command"] == {"range": (0.0, 1.0), "deadband": 0.2, "ramp_m_s2": 1.0}
    assert kw["command"] == {"range": (0.0, 1.0)}  # the caller's dict is not changed
    assert with_keys({"task": "command"}, "command", deadband=0.1)["command"] == {"deadband": 0.1}


@pytest.mark.parametrize("bad", ["1.0", True, [1.0], np.nan, 6.0, -5.5, None])
def test_set_command_refuses_what_the_reset_option_refuses(bad):
    """Finding: set_command took "1.0", True and [1.0] (converted) where reset refused them."""
    env = gym.make("ConstrainedBiped-v0", task="command")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="command"):
        env.unwrapped.set_command(bad)
    with pytest.raises(ValueError, match="command"):
        env.reset(seed=0, options={"command": bad})
    venv = gym.make_vec("ConstrainedBiped-v0", 2, vectorization_mode="vector_entry_point",
                        task="command")  # fmt: skip
    venv.reset(seed=0)
    for value in (bad, [bad, 1.0]):
        with pytest.raises(ValueError, match="command"):
            venv.unwrapped.set_command(value)
    assert env.unwrapped.set_command(np.float32(1.0)) == 1.0
    np.testing.assert_array_equal(venv.unwrapped.set_command([1.0, 0.5]), [1.0, 0.5])


def test_a_misspelt_reset_option_names_the_command_among_the_valid_ones():
    env = gym.make("ConstrainedBiped-v0", task="command")
    with pytest.raises(ValueError, match="comand.*valid: command, mode"):
        env.reset(seed=0, options={"comand": 1.0})


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_command_env_pickles_and_copies_into_an_env_of_its_own(how):
    """Finding: a command-task env could not be pickled (its parts' hooks were closures), and a
    deep copy's hooks would have run the original's parts."""
    import copy
    import pickle

    env = gym.make("ConstrainedBiped-v0", task="command").unwrapped
    env.reset(seed=3, options={"command": 1.2})
    twin = pickle.loads(pickle.dumps(env)) if how == "pickle" else copy.deepcopy(env)
    assert twin.set_command(0.7) == 0.7  # the copy's command only
    assert env.core.commands.v[0] == 1.2
    twin.set_command(1.2)
    acts = np.random.default_rng(0).uniform(-3, 3, (15, 5))
    for a in acts:
        o1, r1, t1, u1, i1 = env.step(a)
        o2, r2, t2, u2, i2 = twin.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2 and t1 == t2 and i1["command_m_s"] == i2["command_m_s"] == 1.2
        if t1 or u1:
            break
