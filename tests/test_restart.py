"""The training's restart rule (``[restart]``): a network that has not found the step draws
again, from training episodes only, saved with the checkpoint and kept by a resume."""

import dataclasses
import json
from types import SimpleNamespace as NS

import numpy as np
import pytest

RULE = {"every": 1_000_000, "window": 100_000, "min_steps": 50, "max": 3}


def _cfg(**kw):
    from training.ppo.config import PPOConfig

    return PPOConfig(**{"env": {"dt": 0.02}, "n_envs": 2, "n_steps": 64, "batch_size": 64, **kw})


@pytest.mark.parametrize(
    ("rule", "match"),
    [
        ({"every": 1000}, "takes every, window, min_steps, max"),
        ({**RULE, "after": 1}, "takes every"),
        ({**RULE, "min_steps": 0}, "min_steps must be a whole number"),
        ({**RULE, "max": 1.5}, "max must be a whole number"),
        ({**RULE, "every": True}, "every must be a whole number"),
        ({**RULE, "max": 101}, "at most 100"),
        ({**RULE, "window": 2_000_000}, "window .* must be at most every"),
    ],
)
def test_a_restart_rule_is_refused_when_wrong(rule, match):
    with pytest.raises(ValueError, match=match):
        _cfg(restart=rule).validate()
    _cfg(restart=RULE).validate()


@pytest.mark.parametrize("kw", [{"teacher": "model"}, {"init_from": "policies/x"},
                                {"critic_warmup": 2}])  # fmt: skip
def test_a_restart_rule_is_refused_where_the_network_does_not_start_random(kw):
    with pytest.raises(ValueError, match="draws a random network: not with"):
        _cfg(restart=RULE, **kw).validate()


def test_untrusted_restart_lists_are_refused():
    from training.ppo.callbacks import check_restart_checked, check_restarts
    from training.ppo.policy_io import UntrustedFileError

    assert check_restarts([1000, 2000], "s", 2000, 3) == [1000, 2000]
    for bad in ([0, 0], [5, 5], [2000, 1000], [1000, 2001], [True], [1.0], "1000", [1, 2, 3, 4]):
        with pytest.raises(UntrustedFileError, match="restarts must be"):
            check_restarts(bad, "s", 2000, 3)
    assert check_restart_checked(None, "s", 10) is None and check_restart_checked(10, "s", 10)
    for bad in (-1, 11, "5", 2.0):
        with pytest.raises(UntrustedFileError, match="restart_checked"):
            check_restart_checked(bad, "s", 10)


def test_a_redrawn_network_is_the_new_seed_s_first_network(tmp_path):
    """After ``redraw_network(model, cfg, s)`` the weights, the initial noise and the bias are
    those a new run with seed s starts from, and the optimiser is new (no moments)."""
    import torch

    from training.ppo.build import initial_actions, make_model, redraw_network, training_env

    cfg = _cfg(seed=3, action_bias_nm=[12.0, 0, 0, 0, 0], log_std_joints=[-5, -4, -4, -3.5, -3])
    venv, vecnorm = training_env(cfg, 3)
    try:
        model = make_model(cfg, vecnorm, tmp_path)
        initial_actions(model, cfg)
        model.learn(128)  # an update: the weights and Adam's moments move
        assert model.policy.optimizer.state
        redraw_network(model, cfg, 1003)
        new = make_model(dataclasses.replace(cfg, seed=1003), vecnorm, tmp_path)
        initial_actions(new, cfg)
        for (k, a), b in zip(model.policy.state_dict().items(),
                             new.policy.state_dict().values(), strict=True):  # fmt: skip
            torch.testing.assert_close(a, b, rtol=0, atol=0, msg=k)
        assert not model.policy.optimizer.state
        assert model.policy.action_net.bias.detach().numpy()[0] == pytest.approx(12 / 150)
        other = make_model(cfg, vecnorm, tmp_path)  # seed 3: another network
        assert not torch.equal(other.policy.action_net.weight, model.policy.action_net.weight)
    finally:
        venv.close()


def _run(tmp_path, *extra):
    from training.ppo import train as train_ppo

    small = ["--n-envs", "2", "--n-steps", "128", "--batch-size", "64", "--n-epochs", "1",
             "--eval-freq", "256", "--eval-episodes", "1", "--checkpoint-freq", "256",
             "--progress", "false"]  # fmt: skip
    return train_ppo.main(["--out-dir", str(tmp_path), *small, *extra])


def test_a_run_without_steps_restarts_up_to_max_and_a_resume_keeps_the_restarts(tmp_path, capsys):
    """The default task's episodes from the mid-stride start end within a few periods with no
    step: every check restarts, up to ``max``; the restarts are in the checkpoint and a
    resume keeps them (no check before a whole window of its own); a tampered list is
    refused."""
    from training.plumbing.common import Refusal
    from training.ppo import train as train_ppo
    from training.ppo.policy_io import load_state, write_manifest

    rule = ["--restart", "every=256", "window=256", "min_steps=1000", "max=2"]
    assert _run(tmp_path / "a", "--total-timesteps", "1024", *rule) == 0
    (run,) = (tmp_path / "a" / "train_ppo").iterdir()
    out = capsys.readouterr().out
    assert out.count("[restart] ") == 2 and "(seed 2000)" in out
    assert load_state(run / "checkpoints" / "latest")["restarts"] == [256, 512]
    assert "; restarts at [256, 512] env steps" in (run / "training_time.txt").read_text()
    from training.evaluation.seed_study import restarts_of, table

    assert restarts_of(run) == [256, 512]
    row = {"ended": "budget", "env_steps": 1024, "wall_s": 3, "steps_mean": 0.0,
           "speed_m_s": 0.0, "success": {"successes": 0, "episodes": 1, "rate": 0.0,
                                         "ci95": [0.0, 0.79], "min_steps": 20}}  # fmt: skip
    text = table(["a", "b"], [{**row, "restarts": [1003520, 2007040]}, {**row, "restarts": []}])
    assert "restarts (env steps)" in text and "| 1.0M, 2.0M |" in text and "| none |" in text
    assert "restarts" not in table(["b"], [{**row, "restarts": []}])
    assert train_ppo.main(["--resume", str(run), "--total-timesteps", "1536",
                           "--progress", "false"]) == 0  # fmt: skip
    assert "[restart] " not in capsys.readouterr().out  # max reached
    assert load_state(run / "checkpoints" / "latest")["restarts"] == [256, 512]
    state = json.loads((run / "checkpoints" / "latest" / "state.json").read_text())
    for bad in ([256, 512, 768], [512, 256], ["256"], 256, [10**9]):
        state["restarts"] = bad
        (run / "checkpoints" / "latest" / "state.json").write_text(json.dumps(state))
        write_manifest(run / "checkpoints" / "latest")  # the attacker rewrites the manifest
        with pytest.raises(Refusal, match="restarts must be the env steps"):
            train_ppo.main(["--resume", str(run), "--total-timesteps", "2048",
                            "--progress", "false"])  # fmt: skip


def test_the_rule_counts_the_steps_of_the_episodes_ended_in_the_window(monkeypatch):
    """Checks at every ``every`` env steps (after the rollout reaching it): fewer than
    ``min_steps`` steps in the episodes that ended in the last ``window`` env steps draws the
    network of seed + 1000 k before the next rollout, at most ``max`` times."""
    import training.ppo.build as build
    from training.ppo.callbacks import restart_rule

    drawn = []
    monkeypatch.setattr(build, "redraw_network", lambda model, cfg, seed: drawn.append(seed))
    cfg = _cfg(seed=7, restart={"every": 1000, "window": 500, "min_steps": 5, "max": 2})
    cfg.validate()
    model = NS(num_timesteps=0, get_env=lambda: None, logger=NS(record=lambda *a: None))
    cb = restart_rule(cfg, [])
    cb.init_callback(model)
    cb.on_training_start({}, {})

    def episodes(t, *steps):  # episodes of two envs ending at env step t
        model.num_timesteps = t
        done = np.array([s is not None for s in steps])
        cb.update_locals({"dones": done, "infos": [{"steps_completed": s or 0} for s in steps]})
        cb.on_step()

    def rollout(t):
        model.num_timesteps = t
        cb.on_rollout_end()
        cb.on_rollout_start()

    episodes(400, 9, None)  # before the first window: not counted
    episodes(600, 3, None)
    episodes(900, None, 1)
    rollout(800)  # before the check
    assert drawn == []
    rollout(1024)  # 3 + 1 < 5 in (524, 1024]
    assert drawn == [1007] and cb.restarts == [1024]
    episodes(1500, 2, None)
    episodes(1900, 3, 2)
    rollout(2048)  # 3 + 2 = 5 in (1548, 2048]: the 2 at 1500 is outside
    assert drawn == [1007]
    rollout(3072)  # no episode ended in the window
    assert drawn == [1007, 2007] and cb.restarts == [1024, 3072]
    rollout(4096)
    assert drawn == [1007, 2007]  # max reached
    ending = restart_rule(cfg, [])  # a restart decided at the last rollout is not made
    ending.init_callback(model)
    model.num_timesteps = 0
    ending.on_training_start({}, {})
    model.num_timesteps = 1024
    ending.on_rollout_end()
    assert ending.restarts == [1024]
    ending.on_training_end()
    assert ending.restarts == [] and ending.pending is None

    def resume(at, checked=None):  # the rule of a session resumed at env step ``at``
        cb = restart_rule(cfg, [1024], checked=checked)
        cb.init_callback(model)
        model.num_timesteps = at
        cb.on_training_start({}, {})
        return cb

    def check(cb, t):
        model.num_timesteps = t
        cb.on_rollout_end()
        cb.on_rollout_start()

    # a resume at 5100 whose last check made was at 4096: the check due at 5000 was not made;
    # it is made once the session has seen a whole window (5600)
    late = resume(5100, checked=4096)
    check(late, 5400)
    assert late.restarts == [1024]  # not a whole window yet
    check(late, 5632)
    assert late.restarts == [1024, 5632] and late.checked == 5632
    made = resume(5100, checked=5000)  # that check made before the checkpoint
    check(made, 5632)
    assert made.restarts == [1024] and made.next_check == 6000
    drawn.clear()
    resumed = resume(5000)  # a resume at 5000: a whole window of its own first
    check(resumed, 6000)
    assert drawn == [2007] and resumed.restarts == [1024, 6000]
