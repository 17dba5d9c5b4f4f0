"""The model-based controller (training/controller/model_controller.py): state from obs,
legal contact forces at the sample, and its documented mid-stride result through the
event-driven env."""

from __future__ import annotations

import json

import numpy as np
import pytest

from biped_constraint_env.env import ConstrainedBipedEnv
from biped_constraint_env.simulator import evaluate
from training.controller.model_controller import (
    DEFAULT_GAINS,
    ModelController,
    midstride_state,
    run_episode,
    state_from_obs,
)


def _env():
    return ConstrainedBipedEnv(dt=0.005, physics={"stop_at_switch": True})


def _start(rate=-1.0):
    s = midstride_state(rate)
    return dict(q=s.q, qd=s.qd, mode=2)


def test_state_from_obs_matches_the_simulator_state():
    env = _env()
    ctl = ModelController(params=env.params, options=env.options)
    obs, _ = env.reset(options=_start())
    for _ in range(120):  # through a heel strike and the renumbering
        obs, _, term, _, _ = env.step(ctl(obs))
        st, got = env.state, state_from_obs(obs)
        assert (int(got.mode), got.stance_side) == (int(st.mode), st.stance_side)
        np.testing.assert_allclose(got.q, st.q, atol=1e-12)
        np.testing.assert_allclose(got.qd, st.qd, atol=1e-12)
        if term:
            break
    assert env.state.stance_side == 1  # the legs did swap roles


def test_torques_keep_the_contacts_pushing_at_the_sample():
    env = _env()
    ctl = ModelController(params=env.params, options=env.options)
    obs, _ = env.reset(options=_start())
    fmin = DEFAULT_GAINS["fmin"]
    for _ in range(60):
        st = env.state
        tau = ctl(obs)
        _, forces, _ = evaluate(env.params, st, tau, env.options)
        assert forces[0] >= fmin - 0.1  # at least fmin (a row of weight 1e3: within 0.1 N)
        assert np.all(np.abs(tau) <= 150.0)
        obs, _, term, _, _ = env.step(tau)
        assert not term


def test_documented_walk():
    """README: on ConstrainedBiped-v0 (strict physics) reset seed 0 walks on; 20 complete
    steps here (the README's 30 s episodes reach 30-31 steps)."""
    import gymnasium as gym

    env = gym.make("ConstrainedBiped-v0").unwrapped
    assert env.options.strict
    ctl = ModelController(params=env.params, options=env.options)
    steps, dist, reason, t = run_episode(env, ctl, seed=0, cap=20)
    assert (steps, reason) == (20, None)
    assert 20.0 < dist < 25.0 and t < 20.0  # about 1.1 m and 0.95 s per step


def test_tune_script_smoke(tmp_path):
    from training.controller.tune import main

    main(
        ["--iterations", "1", "--population", "4", "--cap", "1", "--starts", "2"]
        + ["--out", str(tmp_path)]
    )
    assert (tmp_path / "best_gains.json").exists()
    assert len((tmp_path / "history.csv").read_text().splitlines()) == 1 + 4


def test_tune_start_phase_smoke(tmp_path, monkeypatch):
    """``--phase start``: the same CMA-ES search with the start-from-rest cost."""
    from training.controller import tune

    real = tune.gait_switch_states
    monkeypatch.setattr(tune, "gait_switch_states", lambda g: real(g, range(1), 3.0))
    tune.main(["--phase", "start", "--iterations", "1", "--population", "4", "--seeds", "1",
               "--out", str(tmp_path)])  # fmt: skip
    best = json.loads((tmp_path / "best_start.json").read_text())
    assert set(best) == set(tune.START_BOUNDS)
    assert len((tmp_path / "history.csv").read_text().splitlines()) == 1 + 4


def test_unknown_gain_raises():
    with pytest.raises(ValueError, match="unknown gains"):
        ModelController({"kpp": 1.0})


def test_residual_is_projected_onto_the_constraints():
    """A residual moves the torques, but never so far that a contact pulls at the sample."""
    from training.ppo.sb3_vec import action_map_from

    env = _env()
    ctl = ModelController(params=env.params, options=env.options)
    obs, _ = env.reset(options=_start())
    fmin = DEFAULT_GAINS["fmin"]
    rng = np.random.default_rng(0)
    moved = 0
    for _ in range(40):
        st = env.state
        base = ctl(obs)
        np.testing.assert_allclose(ctl(obs, residual=np.zeros(5)), base, atol=0.05)  # reg 1e-4
        r = rng.uniform(-30.0, 30.0, 5)
        tau = ctl(obs, residual=r)
        _, forces, _ = evaluate(env.params, st, tau, env.options)
        assert forces[0] >= fmin - 0.1
        moved += np.abs(tau - base).max() > 1.0
        obs, _, term, _, _ = env.step(base)
        assert not term
    assert moved > 30  # the residual does act
    amap = action_map_from("model", 7.5)  # the training config's spelling
    a = np.full((1, 5), 0.5)
    np.testing.assert_allclose(amap(a, obs[None]), ctl(obs[None], residual=3.75 * np.ones((1, 5))))
    with pytest.raises(ValueError, match="residual"):
        ctl(obs, residual=np.array([np.nan, 0, 0, 0, 0]))
