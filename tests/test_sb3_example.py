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


def test_the_example_has_help_and_a_checkpoint_every_100k_env_steps():
    import subprocess
    import sys

    r = subprocess.run([sys.executable, str(EXAMPLE), "--help"], capture_output=True, text=True,
                       cwd=ROOT)  # fmt: skip
    assert r.returncode == 0 and "seed" in r.stdout and "env_steps" in r.stdout  # finding: int()
    spec = importlib.util.spec_from_file_location("train_sb3", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.CHECKPOINT_EVERY <= 100_000 and mod.CHECKPOINT_EVERY // mod.N_ENVS >= 1


def test_ctrl_c_saves_the_model_so_far_and_says_so_in_one_line(tmp_path):
    """Finding: Ctrl-C printed a 40-line traceback into the progress bar and saved nothing."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from subprocs import default_sigint

    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_NUM_THREADS": "1"}
    p = subprocess.Popen([sys.executable, str(EXAMPLE), "0", "100000000"], cwd=tmp_path,
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=default_sigint)  # fmt: skip
    out = tmp_path / "runs" / "sb3_example_seed0"
    deadline = time.monotonic() + 240
    while not any(out.glob("PPO_*/events.*")) and time.monotonic() < deadline:
        time.sleep(0.5)  # learning has begun (its TensorBoard log exists)
    time.sleep(3)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 1, stderr[-2000:]
    assert "Traceback" not in stderr
    last = [x for x in stderr.strip().splitlines() if x.strip()][-1]
    assert last.startswith("interrupted at ") and "interrupted_model.zip" in last
    assert (out / "interrupted_model.zip").is_file()
    assert (out / "interrupted_vecnormalize.pkl").is_file()
