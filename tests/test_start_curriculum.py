"""The env's ``set_start`` (single = batched) and the training's start curriculum."""

import json
from collections import deque
from types import SimpleNamespace as NS

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401  (registers the id)
from biped_constraint_env.vector_env import ConstrainedBipedVectorEnv


def test_set_start_draws_the_next_starts_in_both_envs():
    kw = {"dt": 0.02, "observation": ["phase"], "reward": "gait"}
    mix = {"rest": 0.5, "stride": 0.5}
    fresh = gym.make("ConstrainedBiped-v0", start=mix, **kw)
    env = gym.make("ConstrainedBiped-v0", start="midstride", **kw)
    env.reset(seed=3)
    env.step(np.zeros(5, np.float32))
    env.unwrapped.set_start(mix)
    assert env.unwrapped.settings.start.start == (("rest", 0.5), ("stride", 0.5))
    batch = ConstrainedBipedVectorEnv(4, start="midstride", **kw)
    batch.set_start(mix)
    obs_b, _ = batch.reset(seed=10)
    for i in range(4):  # row i of the batch = the single env seeded 10 + i
        want, _ = fresh.reset(seed=10 + i)
        got, _ = env.reset(seed=10 + i)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(obs_b[i], want)
    env.unwrapped.set_start("midstride")  # and back
    np.testing.assert_array_equal(
        env.reset(seed=5)[0],
        gym.make("ConstrainedBiped-v0", start="midstride", **kw).reset(seed=5)[0],
    )


@pytest.mark.parametrize(
    ("start", "match"),
    [
        ("sideways", "start"),
        ({"rest": -1.0}, "weight"),
        ({}, "at least one"),
        ({"reference": 0.5, "midstride": 0.5}, "fixed when the env is made"),
    ],
)
def test_set_start_refuses_what_the_start_setting_refuses(start, match):
    env = gym.make("ConstrainedBiped-v0", dt=0.02)
    batch = ConstrainedBipedVectorEnv(2, dt=0.02)
    for target in (env.unwrapped, batch):
        with pytest.raises(ValueError, match=match):
            target.set_start(start)
        assert target.settings.start.start == "midstride"  # unchanged


def _cfg(**kw):
    from training.ppo.config import PPOConfig

    base = {"env": {"dt": 0.02, "start": "rest"}, "train_env": {"start": "stride"}}
    return PPOConfig(**{**base, "train_episode_s": 5.0, **kw})


@pytest.mark.parametrize(
    ("curriculum", "match"),
    [
        ({"first": "stride"}, "takes first"),
        ({"first": "stride", "until_episode_s": 1.0, "after": 2}, "takes first"),
        ({"first": "sideways", "until_episode_s": 1.0}, "first"),
        ({"first": "stride", "until_episode_s": 5.5}, r"\(0, 5.0\]"),  # never reached
        ({"first": "stride", "until_episode_s": 0}, "until_episode_s"),
        ({"first": "stride", "until_episode_s": True}, "until_episode_s"),
    ],
)
def test_a_start_curriculum_is_refused_when_wrong_or_never_reached(curriculum, match):
    with pytest.raises(ValueError, match=match):
        _cfg(start_curriculum=curriculum).validate()
    _cfg(
        start_curriculum={"first": {"stride": 3, "midstride": 1}, "until_episode_s": 5.0}
    ).validate()


def test_the_curriculum_switches_once_the_last_100_training_episodes_last():
    from training.ppo.callbacks import start_curriculum

    cfg = _cfg(start_curriculum={"first": "midstride", "until_episode_s": 2.0})
    cfg.validate()
    calls = []
    env = NS(env_method=lambda name, start, indices: calls.append((name, start, indices)))
    model = NS(num_timesteps=0, ep_info_buffer=deque(maxlen=100), get_env=lambda: env,
               logger=NS(record=lambda *a: None))  # fmt: skip
    cb = start_curriculum(cfg, None)
    cb.init_callback(model)
    cb.on_training_start({}, {})
    assert calls == [("set_start", "midstride", [0])]
    model.ep_info_buffer.extend({"l": 150} for _ in range(99))  # 3 s, but only 99 episodes
    cb.on_rollout_end()
    model.ep_info_buffer.extend({"l": 40} for _ in range(1))  # 100 episodes, mean 2.98 s
    model.ep_info_buffer.extend({"l": 40} for _ in range(60))  # the last 100: 39 x 3 s, 61 x 0.8 s
    model.num_timesteps = 4096
    cb.on_rollout_end()  # 1.68 s < 2 s
    assert cb.switched_at is None and len(calls) == 1
    model.ep_info_buffer.extend({"l": 100} for _ in range(100))  # 2 s
    model.num_timesteps = 8192
    cb.on_rollout_end()
    assert cb.switched_at == 8192 and calls[-1] == ("set_start", "stride", [0])
    model.ep_info_buffer.extend({"l": 1} for _ in range(100))
    cb.on_rollout_end()
    assert len(calls) == 2  # once only
    resumed = start_curriculum(cfg, 8192)  # a resume after the switch sets nothing
    resumed.init_callback(model)
    resumed.on_training_start({}, {})
    assert len(calls) == 2 and resumed.switched_at == 8192


def test_a_run_saves_the_switch_and_a_resume_keeps_it(tmp_path, capsys):
    from training.plumbing.common import Refusal
    from training.ppo import train as train_ppo
    from training.ppo.policy_io import load_state, write_manifest

    small = ["--n-envs", "2", "--n-steps", "128", "--batch-size", "64", "--n-epochs", "1",
             "--eval-freq", "256", "--eval-episodes", "1", "--checkpoint-freq", "256",
             "--progress", "false"]  # fmt: skip
    # episodes of the default task end within a few periods: 512 env steps hold 100 of them
    curriculum = ["--start-curriculum", 'first="rest"', "until_episode_s=0.001"]
    rc = train_ppo.main(["--out-dir", str(tmp_path), "--total-timesteps", "512", *small,
                         *curriculum])  # fmt: skip
    assert rc == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    switched = load_state(run / "checkpoints" / "latest")["starts_switched_at"]
    assert switched in (256, 512)  # at the end of a rollout
    assert "[starts] " in capsys.readouterr().out
    assert 'first = "rest"' in (run / "config.toml").read_text()
    rc = train_ppo.main(["--resume", str(run), "--total-timesteps", "768", "--progress", "false"])
    assert rc == 0
    assert load_state(run / "checkpoints" / "latest")["starts_switched_at"] == switched
    state = json.loads((run / "checkpoints" / "latest" / "state.json").read_text())
    state["starts_switched_at"] = "soon"  # an untrusted checkpoint is refused, not read
    (run / "checkpoints" / "latest" / "state.json").write_text(json.dumps(state))
    write_manifest(run / "checkpoints" / "latest")  # the attacker rewrites the manifest too
    with pytest.raises(Refusal, match="starts_switched_at must be an env step count"):
        train_ppo.main(["--resume", str(run), "--total-timesteps", "1024", "--progress", "false"])
