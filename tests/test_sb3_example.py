"""The plain-SB3 example (examples/train_sb3.py, shown in docs/sb3.md) runs, briefly."""

from __future__ import annotations

import importlib.util
from pathlib import Path

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
    log = Path(tmp_path) / "log"
    model, env = mod.train(64, seed=0, progress_bar=False, log_dir=log)  # one rollout, 64 x 64
    assert model.num_timesteps >= 64 * 64
    mod.save(model, env, tmp_path / "out")
    assert (tmp_path / "out" / "model.zip").is_file()
    assert (tmp_path / "out" / "vecnormalize.pkl").is_file()
    assert (log / "monitor.csv").is_file() and any(log.glob("PPO_*/events.*"))
    s = mod.evaluate(model, env, episodes=2)
    env.close()  # the monitor file and the TensorBoard writer
    model.logger.close()
    assert s["episodes"] == 2 and 0.0 <= s["rate"] <= 1.0
