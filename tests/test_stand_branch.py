"""The training option ``stand_branch``: a second actor head at a zero command in model 4."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.policies import ActorCriticPolicy

from training.ppo.config import PPOConfig, _choices
from training.ppo.stand_branch import (
    DISCOUNT_ROWS,
    MODE_ENTRY,
    BranchDiscountBuffer,
    StandBranchPolicy,
    branch_from,
    discount_gate,
    truncation_discount,
)

COMMAND = {"env": {"task": "command", "action": "torque"}}
OBS = spaces.Box(-np.inf, np.inf, (27,), np.float32)
ACT = spaces.Box(-1.0, 1.0, (5,), np.float32)


def _policy(seed=0, branch_log_std=-5.0):
    torch.manual_seed(seed)
    return StandBranchPolicy(OBS, ACT, lambda _: 1e-3, net_arch=[16, 16], log_std_init=-3.0,
                             branch_log_std_init=branch_log_std)  # fmt: skip


def _obs(n, command, mode4):
    obs = torch.randn(n, 27)
    obs[:, -1] = torch.as_tensor(command, dtype=torch.float32)
    obs[:, MODE_ENTRY] = torch.where(torch.as_tensor(mode4), 3.0, -0.2)
    return obs


def test_the_branch_acts_only_at_a_zero_command_in_model_4():
    policy = _policy()
    obs = _obs(6, [0.0, 0.0, 0.3, 1e-6, 0.0, 2.0], [True, False, True, True, True, False])
    dist = policy.get_distribution(obs).distribution
    gate = np.array([True, False, False, False, True, False])
    assert policy.gate(obs).numpy().tolist() == gate.tolist()
    walker = policy.action_net(policy.mlp_extractor.forward_actor(obs))
    branch = policy.branch_mean(obs)
    assert not torch.allclose(walker, branch)  # two heads: the test could fail
    assert torch.equal(dist.mean[gate], branch[gate])
    assert torch.equal(dist.mean[~gate], walker[~gate])
    std = dist.stddev.detach().numpy()
    assert std[gate] == pytest.approx(np.full((2, 5), np.exp(-5.0)), rel=1e-5)
    assert std[~gate] == pytest.approx(np.full((4, 5), np.exp(-3.0)), rel=1e-5)
    # predict (the run-time route) goes through the gate too
    det, _ = policy.predict(obs.numpy(), deterministic=True)
    np.testing.assert_allclose(det, np.clip(dist.mean.detach().numpy(), -1, 1), atol=1e-6)


def test_the_branch_critic_values_the_gated_rows_in_every_pass():
    policy = _policy()
    with torch.no_grad():
        policy.branch_value_scale.fill_(2.5)
    obs = _obs(6, [0.0, 0.0, 0.3, 0.0, 1.0, 0.0], [True, False, True, True, True, False])
    gate = policy.gate(obs)
    with torch.no_grad():
        walker = policy.value_net(policy.mlp_extractor.forward_critic(obs))
        branch = policy.branch_value(policy.branch_value_net(obs)) * 2.5  # the input map: 1, 0
        want = torch.where(gate[:, None], branch, walker)
        assert not torch.allclose(walker[gate], want[gate])
        _, v_rollout, _ = policy(obs)
        v_update, _, _ = policy.evaluate_actions(obs, torch.zeros(6, 5))
        v_boot = policy.predict_values(obs)
    for v in (v_rollout, v_update, v_boot):
        torch.testing.assert_close(v, want)


def test_rollout_and_update_agree_and_each_head_learns_only_from_its_rows():
    policy = _policy()
    obs = _obs(64, np.where(np.arange(64) % 3 == 0, 0.0, 1.0), np.arange(64) % 2 == 0)
    with torch.no_grad():
        actions, _, logp = policy(obs)
        _, logp2, _ = policy.evaluate_actions(obs, actions)
    assert torch.allclose(logp, logp2, atol=1e-5)
    gate = policy.gate(obs)
    assert 0 < gate.sum() < 64
    actor = ("branch_net", "branch_action", "branch_log_std")
    for rows, learns, still in ((gate, actor, ("action_net",)), (~gate, ("action_net",), actor)):
        policy.zero_grad(set_to_none=True)
        _, lp, _ = policy.evaluate_actions(obs[rows], actions[rows])
        lp.sum().backward()  # the log-probability: the actors' gradient alone
        grads = {k: p.grad for k, p in policy.named_parameters()}
        assert any(g is not None and g.abs().sum() > 0 for k, g in grads.items()
                   if k.startswith(learns))  # fmt: skip
        assert all(g is None or g.abs().sum() == 0 for k, g in grads.items()
                   if k.startswith(still))  # fmt: skip
    # the walker's actor layers get nothing from the branch's rows either
    policy.zero_grad(set_to_none=True)
    _, lp, _ = policy.evaluate_actions(obs[gate], actions[gate])
    lp.sum().backward()
    g = policy.mlp_extractor.policy_net[0].weight.grad
    assert g is None or g.abs().sum() == 0


def test_a_branch_from_another_actor_computes_that_actors_action_on_its_own_input():
    torch.manual_seed(1)
    source = ActorCriticPolicy(OBS, ACT, lambda _: 1e-3, net_arch=[16, 16], log_std_init=-4.0)
    rng = np.random.default_rng(0)
    src_mean, src_var = rng.normal(0, 1, 27), rng.uniform(0.01, 2.0, 27)
    src_var[[0, 16]] = 0.0  # entries that never varied in the source's data
    run_mean, run_var = rng.normal(0, 1, 27), rng.uniform(0.1, 3.0, 27)
    run_mean[MODE_ENTRY] = 0.3  # a share of the run's data in model 4
    norm = {"obs_mean": src_mean, "obs_var": src_var, "epsilon": 1e-8, "clip_obs": 10.0,
            "ret_var": 4.0}  # fmt: skip
    policy = _policy()
    branch_from(policy, source, norm, run_mean, run_var, 1e-8, 9.0)
    raw = rng.normal(run_mean, np.sqrt(run_var) * 3, (200, 27))
    raw[:, [0, 16]] = src_mean[[0, 16]]  # as in the source's data
    x_run = np.clip((raw - run_mean) / np.sqrt(run_var + 1e-8), -10, 10)
    inside = np.all(np.abs((raw - run_mean) / np.sqrt(run_var + 1e-8)) < 10, axis=1)
    x_src = np.clip((raw - src_mean) / np.sqrt(src_var + 1e-8), -10, 10)
    with torch.no_grad():
        mine = policy.branch_mean(torch.as_tensor(x_run, dtype=torch.float32)).numpy()
        theirs = source.action_net(source.mlp_extractor.forward_actor(
            torch.as_tensor(x_src, dtype=torch.float32))).numpy()  # fmt: skip
    assert (x_src == 10).any() and inside.sum() > 100  # the source's clip is exercised
    np.testing.assert_allclose(mine[inside], theirs[inside], atol=1e-5)
    assert torch.equal(policy.branch_log_std.detach(), source.log_std.detach())
    with torch.no_grad():  # its critic too, in this run's return units
        mine_v = policy.branch_values(torch.as_tensor(x_run, dtype=torch.float32)).numpy()
        theirs_v = source.value_net(source.mlp_extractor.forward_critic(
            torch.as_tensor(x_src, dtype=torch.float32))).numpy()  # fmt: skip
    np.testing.assert_allclose(mine_v[inside], theirs_v[inside] * np.sqrt(4.0 / 9.0), atol=1e-5)
    # statistics of nothing but model 4 would hide the model from the gate: refused
    all_four = run_mean.copy()
    all_four[MODE_ENTRY] = 1.0
    with pytest.raises(ValueError, match="nothing but model 4"):
        branch_from(_policy(), source, norm, all_four, run_var, 1e-8, 9.0)
    # an entry the source never saw vary reads 0 whatever its value now
    moved = x_run.copy()
    moved[:, 16] = 5.0
    with torch.no_grad():
        a, b = (policy.branch_mean(torch.as_tensor(x, dtype=torch.float32)) for x in (x_run, moved))
    assert torch.equal(a, b)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"stand_branch": True, "env": {"task": "walk"}}, "command as the observation's last"),
        ({"stand_branch": True, "stand_std_nm": 0.5, **COMMAND}, "give one"),
        ({"stand_branch": True, "use_sde": True, **COMMAND}, "use_sde"),
        ({"stand_branch_from": "x", **COMMAND}, "goes with --stand-branch and --init-from"),
        ({"stand_branch": True, "stand_branch_from": "x", **COMMAND}, "--init-from"),
        ({"stand_branch_frozen": True, **COMMAND}, "goes with --stand-branch"),
        ({"walker_frozen": True, **COMMAND}, "--walker-frozen goes with --stand-branch"),
        ({"learn_rows": "zero_command", **COMMAND}, "--learn-rows goes with --stand-branch"),
        ({"brake_branch": True, **COMMAND}, "--brake-branch goes with --stand-branch"),
        ({"stand_branch": True, "learn_rows": "zero_command", "ent_coef": 0.01, **COMMAND},
         "--ent-coef 0"),
        ({"stand_branch": True, "learn_rows": "stops", **COMMAND}, "learn.rows"),
        ({"stand_branch": True, "walker_frozen": True, "stand_branch_frozen": True, **COMMAND},
         "no actor"),
        ({"stand_gamma": 0.99, **COMMAND}, "--stand-gamma goes with --stand-branch"),
        ({"stand_branch": True, "stand_gamma": 1.0, **COMMAND}, "below 1"),
        ({"stand_branch": True, "stand_gamma_rows": "zero_command", **COMMAND},
         "--stand-gamma-rows goes with --stand-gamma"),
        ({"stand_branch": True, "stand_gamma": 0.99, "stand_gamma_rows": "stand", **COMMAND},
         "stand.gamma.rows"),
        ({"stand_branch": True, "stand_branch_from": "x", "init_from": "y",
          "init_normalizer": "fresh", **COMMAND}, "snapshot"),
    ],
)  # fmt: skip
def test_the_option_is_refused_where_it_means_nothing(kwargs, match):
    with pytest.raises(ValueError, match=match):
        PPOConfig(**kwargs).validate()
    PPOConfig(stand_branch=True, target_kl=0.02, **COMMAND).validate()


def test_the_discount_rows_are_the_configs_choices():
    assert _choices()["stand_gamma_rows"] == DISCOUNT_ROWS
    with pytest.raises(ValueError, match="rows must be one of"):
        discount_gate(_obs(2, [0.0, 1.0], [True, True]), "stand")
    with pytest.raises(ValueError, match="rows must be one of"):
        truncation_discount(0.99, "stand")


def _filled_buffer(stand_gamma, gamma=0.9, lam=0.95, seed=0, rows="branch"):
    """A rollout of 4 steps x 3 envs: branch rows where the command is 0 in model 4; the
    gate of ``rows`` returned."""
    rng = np.random.default_rng(seed)
    kw = {"gamma": gamma, "gae_lambda": lam, "device": "cpu", "n_envs": 3}
    buf = (BranchDiscountBuffer(4, OBS, ACT, stand_gamma=stand_gamma, rows=rows, **kw)
           if stand_gamma else RolloutBuffer(4, OBS, ACT, **kw))  # fmt: skip
    commands = [[0.0, 0.0, 1.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    mode4 = [[True, False, True], [True, True, True], [False, True, True], [True, True, False]]
    starts = [[1, 1, 1], [0, 0, 0], [0, 1, 0], [0, 0, 0]]
    for step in range(4):
        obs = _obs(3, commands[step], mode4[step]).numpy()
        value, log_prob = (torch.as_tensor(rng.normal(size=3)) for _ in range(2))
        buf.add(obs, rng.normal(size=(3, 5)), rng.normal(size=3), np.array(starts[step]), value,
                log_prob)  # fmt: skip
    last_values, dones = torch.as_tensor(rng.normal(size=3)), np.array([False, True, False])
    buf.compute_returns_and_advantage(last_values, dones)
    gate = np.array(commands) == 0
    if rows == "branch":
        gate &= np.array(mode4)
    return buf, gate, np.array(starts), last_values.numpy(), dones


@pytest.mark.parametrize("rows", DISCOUNT_ROWS)
def test_the_branch_discount_is_sb3s_gae_at_one_discount_and_each_rows_own_otherwise(rows):
    ours, _, _, _, _ = _filled_buffer(stand_gamma=0.9, rows=rows)
    sb3, _, _, _, _ = _filled_buffer(stand_gamma=0.0)  # SB3's own buffer, same data
    np.testing.assert_allclose(ours.advantages, sb3.advantages, rtol=1e-6)
    np.testing.assert_allclose(ours.returns, sb3.returns, rtol=1e-6)
    # lambda = 1: the return is the discounted sum, each step discounting what follows by its
    # own row's factor, bootstrapped at the rollout's end (by hand, not GAE's recursion)
    buf, gate, starts, last_values, dones = _filled_buffer(stand_gamma=0.99, lam=1.0, rows=rows)
    assert 0 < gate.sum() < gate.size  # both kinds of rows: the test could fail
    other, _, _, _, _ = _filled_buffer(stand_gamma=0.99, lam=1.0, rows=sorted(
        set(DISCOUNT_ROWS) - {rows})[0])  # fmt: skip
    assert not np.allclose(other.returns, buf.returns)  # the rows matter: model 4 or not
    np.testing.assert_array_equal(buf.step_gammas(), np.where(gate, 0.99, 0.9).astype(np.float32))
    for env in range(3):
        ret = last_values[env] * (1.0 - dones[env])
        for step in reversed(range(4)):
            if step < 3 and starts[step + 1, env]:
                ret = 0.0  # the next step began a new episode
            ret = buf.rewards[step, env] + (0.99 if gate[step, env] else 0.9) * ret
            assert buf.returns[step, env] == pytest.approx(ret, rel=1e-5)
    plain, _, _, _, _ = _filled_buffer(stand_gamma=0.9, lam=1.0)
    assert not np.allclose(plain.returns, buf.returns)
    with pytest.raises(ValueError, match="stand_gamma"):
        BranchDiscountBuffer(4, OBS, ACT, stand_gamma=1.0)
    with pytest.raises(ValueError, match="rows"):
        BranchDiscountBuffer(4, OBS, ACT, stand_gamma=0.99, rows="stand")


@pytest.mark.parametrize("rows", DISCOUNT_ROWS)
def test_a_time_limit_on_a_branch_row_bootstraps_at_the_branch_discount(rows):
    from types import SimpleNamespace

    policy = _policy()
    # rows 0, 1 gated in model 4; row 3 at a zero command in another contact state
    last = _obs(4, [0.0, 0.0, 1.0, 0.0], [True, True, True, False]).numpy()
    # the transition's start decides, not where it ended: row 0 ends at a nonzero command
    terminal = _obs(4, [0.5, 0.0, 0.0, 0.0], [True] * 4).numpy()
    model = SimpleNamespace(gamma=0.9, _last_obs=last, policy=policy, num_timesteps=0)
    cb = truncation_discount(0.99, rows)
    cb.init_callback(model)
    rewards = np.array([1.0, 2.0, 3.0, 4.0], dtype=np.float32)
    dones = np.array([True, True, True, True])
    cut = [True, False, True, True]  # row 1 ended by a fall: no bootstrap at all
    infos = [{"terminal_observation": terminal[i], "TimeLimit.truncated": cut[i]} for i in range(4)]
    cb.update_locals({"rewards": rewards, "dones": dones, "infos": infos})
    assert cb.on_step()
    with torch.no_grad():
        v = policy.predict_values(torch.as_tensor(terminal))[:, 0].numpy()
    assert min(abs(v[0]), abs(v[3])) > 1e-2  # a bootstrap the tolerance below can see
    want = [1.0 + 0.09 * v[0], 2.0, 3.0, 4.0]  # only the gated, time-limited rows move
    if rows == "zero_command":
        want[3] += 0.09 * v[3]
    np.testing.assert_allclose(rewards, want, rtol=1e-5)


def test_a_run_with_a_branch_from_a_walker_and_a_stander_saves_and_loads_it(tmp_path, monkeypatch):
    """A walker (init_from) and a stander (stand_branch_from) start one network, loaded as any."""
    from training.ppo import stand_branch
    from training.ppo import train as train_ppo
    from training.ppo.policy_io import load_policy

    calls = {"gae": 0, "steps": 0, "discounts": [], "rows": []}  # --stand-gamma reaches PPO
    gae = BranchDiscountBuffer.compute_returns_and_advantage

    def counted_gae(self, *args, **kwargs):
        calls["gae"] += 1
        calls["discounts"].append((self.stand_gamma, self.rows))
        return gae(self, *args, **kwargs)

    def counted_callback(g, rows):
        calls["rows"].append(rows)
        cb = truncation_discount(g, rows)
        on_step = cb._on_step
        cb._on_step = lambda: calls.__setitem__("steps", calls["steps"] + 1) or on_step()
        return cb

    monkeypatch.setattr(BranchDiscountBuffer, "compute_returns_and_advantage", counted_gae)
    monkeypatch.setattr(stand_branch, "truncation_discount", counted_callback)

    flags = ["--total-timesteps", "128", "--n-envs", "2", "--n-steps", "32", "--batch-size",
             "64", "--n-epochs", "1", "--eval-freq", "1000", "--checkpoint-freq", "64",
             "--progress", "false", "--env", "task=command"]  # fmt: skip
    for name in ("walker", "stander"):  # plain actors that read the command in m/s
        rc = train_ppo.main([*flags, "--stand-std-nm", "0.5", "--out-dir", str(tmp_path / name)])
        assert rc == 0
    walker, stander = ((tmp_path / n / "train_ppo").iterdir().__next__() for n in
                       ("walker", "stander"))  # fmt: skip
    tiny = ["--learning-rate", "1e-12"]
    rc = train_ppo.main([*flags, *tiny, "--out-dir", str(tmp_path / "b"), "--init-from",
                         str(walker), "--stand-branch", "--stand-branch-from",
                         str(stander), "--stand-gamma", "0.99", "--stand-gamma-rows",
                         "zero_command"])  # fmt: skip
    assert rc == 0
    assert calls["gae"] >= 2  # 128 steps: 2 rollouts
    assert set(calls["discounts"]) == {(0.99, "zero_command")} and calls["rows"] == ["zero_command"]
    assert calls["steps"] >= 64  # the time-limit bootstrap's callback saw every env step
    (run,) = (tmp_path / "b" / "train_ppo").iterdir()
    record = json.loads((run / "init_from.json").read_text())
    assert record["stand_branch_from"]["policy"] == str(stander)
    assert len(record["stand_branch_from"]["policy_sha256"]) == 64
    policy, norm, cfg, _ = load_policy(run, "final")
    assert isinstance(policy, StandBranchPolicy) and cfg.stand_branch and cfg.stand_gamma == 0.99
    assert norm.mean[-1] == 0.0 and norm.var[-1] == 1.0  # the gate reads the command in m/s
    # rows at a zero command in model 4 act as the stander, the others as the walker
    # the branch is the stander's actor behind the map from the walker's normalised input to
    # the stander's (the statistics at the start; both runs already read the command in m/s)
    s_pol, s_norm, _, _ = load_policy(stander)
    w_pol, w_norm, _, _ = load_policy(walker)
    for mine, theirs in ((policy.branch_net, s_pol.mlp_extractor.policy_net),
                         (policy.branch_action, s_pol.action_net),
                         (policy.branch_value_net, s_pol.mlp_extractor.value_net),
                         (policy.branch_value, s_pol.value_net),
                         (policy.mlp_extractor, w_pol.mlp_extractor),
                         (policy.action_net, w_pol.action_net)):  # fmt: skip
        for a, b in zip(mine.state_dict().values(), theirs.state_dict().values(), strict=True):
            np.testing.assert_allclose(a.numpy(), b.numpy(), atol=1e-6)
    # what the stander's actor read (the rest, which barely varied there: 0, as it was)
    read = np.sqrt(s_norm.var + 1e-8) >= 0.01 * np.sqrt(w_norm.var + 1e-8)
    scale = np.where(read, np.sqrt(w_norm.var + 1e-8) / np.sqrt(s_norm.var + 1e-8), 0.0)
    shift = np.where(read, (w_norm.mean - s_norm.mean) / np.sqrt(s_norm.var + 1e-8), 0.0)
    np.testing.assert_allclose(policy.branch_input.scale.numpy(), scale, rtol=1e-6)
    np.testing.assert_allclose(policy.branch_input.shift.numpy(), shift, rtol=1e-6, atol=1e-6)
    assert read.any()
    # the run's observation statistics stayed the start's (the map is exact for them)
    np.testing.assert_array_equal(norm.mean, w_norm.mean)
    np.testing.assert_array_equal(norm.var, w_norm.var)
    # a stage with the branch's actor frozen: it stays the stander's; its critic learns
    rc = train_ppo.main([*flags, "--learning-rate", "1e-2", "--out-dir", str(tmp_path / "f"),
                         "--init-from", str(run), "--stand-branch", "--stand-branch-frozen",
                         "--critic-warmup", "1"])  # fmt: skip
    assert rc == 0
    (frozen,) = (tmp_path / "f" / "train_ppo").iterdir()
    after, _, _, _ = load_policy(frozen, "final")
    for name, v in after.state_dict().items():
        same = torch.equal(v, policy.state_dict()[name])
        if name.startswith(("branch_net.", "branch_action.", "branch_log_std")):
            assert same, name
        elif name in ("value_net.weight", "action_net.weight"):
            assert not same, name  # the test could fail: the rest learned
    # a stage with the walker's actor frozen (standing starts at a zero command: branch rows):
    # it stays as it was; the branch and the critics learn
    rc = train_ppo.main([*flags, "--learning-rate", "1e-2", "--out-dir", str(tmp_path / "w"),
                         "--init-from", str(run), "--stand-branch", "--walker-frozen",
                         "--train-env", "start={stand = 1.0}", "--train-env",
                         "command={range = [0.0, 2.0], zero_fraction = 1.0}"])  # fmt: skip
    assert rc == 0
    (still,) = (tmp_path / "w" / "train_ppo").iterdir()
    after, _, _, _ = load_policy(still, "final")
    walker_names = ("mlp_extractor.policy_net.", "action_net.", "log_std")
    for name, v in after.state_dict().items():
        same = torch.equal(v, policy.state_dict()[name])
        if name.startswith(walker_names):
            assert same, name
        elif name in ("value_net.weight", "branch_value.weight", "branch_action.weight"):
            assert not same, name  # the test could fail: the rest learned
    # learning from the stops alone: with no zero command in training no actor moves at all;
    # with every command zero, the walker (its braking rows) learns
    for zero, name in ((0.0, "n"), (1.0, "z")):
        rc = train_ppo.main([*flags, "--learning-rate", "1e-2", "--out-dir", str(tmp_path / name),
                             "--init-from", str(run), "--stand-branch", "--learn-rows",
                             "zero_command", "--train-env",
                             f"command={{range = [0, 2], zero_fraction = {zero}}}"])  # fmt: skip
        assert rc == 0
        (out,) = (tmp_path / name / "train_ppo").iterdir()
        after, _, cfg, _ = load_policy(out, "final")
        assert cfg.learn_rows == "zero_command"
        before = policy.state_dict()
        moved = {k for k, v in after.state_dict().items() if not torch.equal(v, before[k])}
        assert "value_net.weight" in moved  # the critic learns from every row
        actor = {k for k in moved if k.startswith((*walker_names, "branch_net.", "branch_action."))}
        assert (not actor) if zero == 0.0 else ("action_net.weight" in actor), (zero, actor)
    # a braking actor: starts as the walker's copy (the network acts as its start on every
    # row), acts on the rows commanded to stop outside model 4, learns there with the walker
    # frozen (every command zero, starts mid-stride: braking rows)
    rc = train_ppo.main([*flags, "--learning-rate", "1e-2", "--out-dir", str(tmp_path / "k"),
                         "--init-from", str(run), "--stand-branch", "--brake-branch",
                         "--walker-frozen", "--train-env", "start={stride = 1.0}", "--train-env",
                         "command={range = [0, 2], zero_fraction = 1.0}"])  # fmt: skip
    assert rc == 0
    (braked,) = (tmp_path / "k" / "train_ppo").iterdir()
    after, _, cfg, _ = load_policy(braked, "final")
    assert cfg.brake_branch and after.brake_branch
    before = policy.state_dict()
    start_of = {
        "brake_net.": "mlp_extractor.policy_net.",
        "brake_action.": "action_net.",
        "brake_log_std": "log_std",
    }  # the braking actor started as the walker's copy

    def start_value(k):
        for mine, src in start_of.items():
            if k.startswith(mine):
                return before[src + k[len(mine) :]]
        return before[k]

    moved = {k for k, v in after.state_dict().items() if not torch.equal(v, start_value(k))}
    assert not {k for k in moved if k.startswith(walker_names)}
    assert {"brake_action.weight", "brake_net.0.weight"} <= moved  # the test could fail
    obs = torch.as_tensor(np.random.default_rng(0).normal(size=(400, policy.features_dim)),
                          dtype=torch.float32)  # fmt: skip
    obs[::2, -1] = 0.0  # half commanded to stop
    brake = StandBranchPolicy.brake_gate(obs)
    assert brake.any() and not (brake & StandBranchPolicy.gate(obs)).any()
    # the gates by their definition: a zero command in model 4 stands, elsewhere brakes
    rows = torch.zeros(4, policy.features_dim)
    rows[:, -1] = torch.tensor([0.0, 0.0, 0.5, 0.5])  # the command [m/s]
    rows[:, MODE_ENTRY] = torch.tensor([3.0, -0.2, 3.0, -0.2])  # model 4 or not (normalised)
    assert StandBranchPolicy.gate(rows).tolist() == [True, False, False, False]
    assert StandBranchPolicy.brake_gate(rows).tolist() == [False, True, False, False]
    with torch.no_grad():
        mine, theirs = (p.get_distribution(obs).distribution.mean for p in (after, policy))
        walk = obs[:, -1] != 0
        assert torch.equal(mine[walk], theirs[walk])  # the walk at every command as it was
        assert not torch.allclose(mine[brake], theirs[brake])  # the braking rows learned
    # its start acted as the start's network on every row (a copy, before any update)
    rc = train_ppo.main([*flags, *tiny, "--out-dir", str(tmp_path / "k0"), "--init-from",
                         str(run), "--stand-branch", "--brake-branch"])  # fmt: skip
    assert rc == 0
    (copied,) = (tmp_path / "k0" / "train_ppo").iterdir()
    start, _, _, _ = load_policy(copied, "best" if (copied / "best").exists() else "final")
    sd = start.state_dict()
    for mine, src in start_of.items():
        for k in (k for k in sd if k.startswith(mine)):
            np.testing.assert_allclose(sd[k].numpy(), sd[src + k[len(mine) :]].numpy(), atol=1e-6)
    # from a plain walker (no branch) with the config's own initial noise: the copy is made
    # once the walker is as the run starts it, so it acts as the walker, noise included
    rc = train_ppo.main([*flags, *tiny, "--out-dir", str(tmp_path / "k2"), "--init-from",
                         str(walker), "--stand-branch", "--brake-branch", "--action-std-nm",
                         "0.3"])  # fmt: skip
    assert rc == 0
    (k2,) = (tmp_path / "k2" / "train_ppo").iterdir()
    start, _, cfg2, _ = load_policy(k2, "final")
    sd = start.state_dict()
    gear = torch.as_tensor(cfg2.action_map().gear, dtype=torch.float32)
    np.testing.assert_allclose(sd["brake_log_std"].numpy(), torch.log(0.3 / gear).numpy(),
                               rtol=1e-5)  # fmt: skip
    for mine, src in start_of.items():
        for k in (k for k in sd if k.startswith(mine)):
            np.testing.assert_allclose(sd[k].numpy(), sd[src + k[len(mine) :]].numpy(), atol=1e-6)
    with pytest.raises(SystemExit, match="give --brake-branch"):
        train_ppo.main([*flags, "--out-dir", str(tmp_path / "k1"), "--init-from", str(braked),
                        "--stand-branch"])  # fmt: skip
    # a later stage from it keeps its branch and needs the option
    rc = train_ppo.main([*flags, "--out-dir", str(tmp_path / "c"), "--init-from", str(run),
                         "--stand-branch"])  # fmt: skip
    assert rc == 0
    with pytest.raises(SystemExit, match="has a standing branch; give --stand-branch"):
        train_ppo.main([*flags, "--out-dir", str(tmp_path / "d"), "--init-from", str(run)])
    assert Path(run / "config.toml").read_text().count("stand_branch = true") == 1
