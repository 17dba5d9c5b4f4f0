"""The plain-SB3 example (examples/train_sb3.py, shown in docs/sb3.md) runs, briefly."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "train_sb3.py"


def test_the_docs_show_the_example_as_it_is():
    doc = (ROOT / "docs" / "sb3.md").read_text()
    code = doc.split("```python\n", 1)[1].split("```", 1)[0]
    assert code == EXAMPLE.read_text()


def test_the_example_trains_saves_logs_and_evaluates(tmp_path):
    spec = importlib.util.spec_from_file_location("train_sb3", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = Path(tmp_path) / "out"  # two rollouts of 64 x 64, an evaluation after the first
    model, normaliser = mod.train(0, 2 * 64 * 64, out, progress_bar=False, eval_every=64 * 64)
    assert model.num_timesteps >= 64 * 64  # the best of the evaluations, saved and reloaded
    assert (out / "best_model.zip").is_file() and (out / "vecnormalize.pkl").is_file()
    assert (out / "monitor.csv").is_file() and any(out.glob("PPO_*/events.*"))
    with np.load(out / "evaluations.npz") as ev:  # SB3's curve: 30 episodes per evaluation
        assert ev["results"].shape[1] == 30 and len(ev["timesteps"]) >= 1
    assert not normaliser.training and normaliser.obs_rms.count >= 64 * 64
    s = mod.evaluate(model, normaliser, episodes=2)
    assert s["episodes"] == 2 and 0.0 <= s["rate"] <= 1.0


def test_the_example_stops_once_every_evaluation_episode_lasts():
    spec = importlib.util.spec_from_file_location("train_sb3", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)

    class Parent:
        evaluations_length: list = []

    stop = mod.StopWhenEveryEpisodeLasts(evals=2)
    stop.parent = Parent()
    full = round(mod.EVAL_S / mod.DT)
    verdicts = []
    for lengths in ([full] * 30, [full] * 29 + [40], [full] * 30, [full] * 30):
        Parent.evaluations_length.append(lengths)
        verdicts.append(stop._on_step())
    assert verdicts == [True, True, True, False]  # two full evaluations in a row stop it
