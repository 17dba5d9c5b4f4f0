"""Runs killed at any instant resume to their own saved total, in every phase.

Each test starts ``python -m training.ppo.train`` as a separate process, kills it with SIGKILL
(no clean-up runs), and continues the run with ``--resume``.
"""

from __future__ import annotations

import csv
import json
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from subprocs import start

from training.ppo import train as train_ppo
from training.ppo.policy_io import STATE_FILE, find_snapshot, load_state, write_manifest

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--n-envs", "2", "--n-steps", "128", "--batch-size", "128", "--n-epochs", "1"]
SMALL += ["--eval-episodes", "1", "--progress", "false"]
TEACHER = ["--teacher", "model", "--gear", "60", "150", "150", "80", "65"]
TEACHER += ["--bc-episodes0", "2", "--bc-periods0", "60", "--bc-rounds", "3"]
TEACHER += ["--bc-episodes", "1", "--bc-periods", "30", "--bc-grad-steps", "40"]
WAIT_S = 300
"""Longest wait for the process to reach the state where it is killed (a guard, not a bound
on speed)."""


def _start(out: Path, args: list[str]) -> subprocess.Popen:
    return start("training.ppo.train", ["--out-dir", str(out), *args])


def _run_dir(out: Path) -> Path:
    (run,) = (out / "train_ppo").iterdir()
    return run


def _kill_when(proc: subprocess.Popen, ready) -> None:
    t0 = time.time()
    while not ready():
        assert proc.poll() is None, proc.stderr.read().decode()[-3000:]
        assert time.time() - t0 < WAIT_S, "the run never reached the state to kill it in"
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stderr.close()


def test_killed_ppo_run_resumes_to_its_own_total_and_keeps_its_best(tmp_path):
    total = 8192
    proc = _start(
        tmp_path,
        SMALL + ["--total-timesteps", str(total), "--checkpoint-freq", "512"]
        + ["--eval-freq", "2048"],
    )  # fmt: skip
    out = tmp_path / "train_ppo"
    _kill_when(proc, lambda: any(out.glob("*/checkpoints/latest/" + STATE_FILE)))
    run = _run_dir(tmp_path)
    killed_at = load_state(find_snapshot(run, "checkpoint"))["num_timesteps"]
    assert killed_at < total
    # a best evaluation of an earlier session: no worse one may replace it
    best = run / "best"
    best.mkdir(exist_ok=True)
    (best / STATE_FILE).write_text(json.dumps({"num_timesteps": 0, "score": 1e9}))
    write_manifest(best)  # a complete snapshot: its manifest is written last
    assert train_ppo.main(["--resume", str(run), "--progress", "false"]) == 0  # no total given
    n = load_state(run / "final")["num_timesteps"]
    assert total <= n < total + 256  # the saved total, not the CLI default (3M)
    assert load_state(run / "best")["score"] == 1e9
    monitors = sorted(p.name for p in run.glob("*.monitor.csv"))
    assert monitors == sorted(["0.monitor.csv", f"{killed_at}.monitor.csv"])


def test_resume_refuses_to_change_the_runs_settings(tmp_path):
    assert train_ppo.main(SMALL + ["--out-dir", str(tmp_path), "--total-timesteps", "256"]) == 0
    run = _run_dir(tmp_path)
    with pytest.raises(SystemExit, match="learning_rate"):
        train_ppo.main(["--resume", str(run), "--learning-rate", "0.1"])


def _imitation_rows(run: Path) -> list[tuple]:
    with open(run / "imitation.csv") as fh:
        return [
            (r["round"], r["samples"], r["mse"], r["student_steps"]) for r in csv.DictReader(fh)
        ]


def test_killed_imitation_resumes_to_the_same_result(tmp_path):
    args = SMALL + TEACHER + ["--total-timesteps", "256", "--eval-freq", "100000"]
    whole = tmp_path / "whole"
    assert train_ppo.main(args + ["--out-dir", str(whole)]) == 0
    killed = tmp_path / "killed"
    proc = _start(killed, args)
    ckpt = f"*/{train_ppo.IMITATION_CKPT}/{STATE_FILE}"
    _kill_when(proc, lambda: any((killed / "train_ppo").glob(ckpt)))
    run = _run_dir(killed)
    assert not (run / "imitation.csv").exists()  # killed inside the imitation phase
    assert train_ppo.main(["--resume", str(run), "--progress", "false"]) == 0
    assert _imitation_rows(run) == _imitation_rows(_run_dir(whole))
    assert [r[0] for r in _imitation_rows(run)] == ["0", "1", "2", "3"]
    assert load_state(run / "final")["num_timesteps"] >= 256


@pytest.mark.slow
def test_random_kills_always_leave_a_resumable_run(tmp_path):
    """Eight SIGKILLs at random instants of one run: each time it resumes and goes on."""
    rng = np.random.default_rng(0)
    total = 60_000
    args = SMALL + ["--total-timesteps", str(total), "--checkpoint-freq", "256"]
    proc = _start(tmp_path, args + ["--eval-freq", "4096"])
    out = tmp_path / "train_ppo"
    _kill_when(proc, lambda: any(out.glob("*/checkpoints/latest/" + STATE_FILE)))
    run = _run_dir(tmp_path)
    for _ in range(8):
        before = load_state(find_snapshot(run, "checkpoint"))["num_timesteps"]
        proc = _start(tmp_path, ["--resume", str(run), "--progress", "false"])
        time.sleep(rng.uniform(6.0, 12.0))  # imports, then somewhere in training
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
        after = load_state(find_snapshot(run, "checkpoint"))["num_timesteps"]
        assert after >= before
    assert train_ppo.main(["--resume", str(run), "--progress", "false"]) == 0
    assert load_state(run / "final")["num_timesteps"] >= total


def test_interrupted_run_resumes_and_a_second_writer_is_refused(tmp_path):
    """Ctrl-C in PPO leaves a resumable run; while one resume runs, a second is refused by
    name (the holder's pid); once the holder is killed, the lock is free again."""
    total = 8192
    args = SMALL + ["--total-timesteps", str(total), "--checkpoint-freq", "512"]
    proc = _start(tmp_path, args + ["--eval-freq", "100000"])
    out = tmp_path / "train_ppo"
    t0 = time.time()
    while not any(out.glob("*/checkpoints/latest/" + STATE_FILE)):
        assert proc.poll() is None and time.time() - t0 < WAIT_S
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    proc.wait()
    proc.stderr.close()
    run = _run_dir(tmp_path)
    holder = _start(tmp_path, ["--resume", str(run), "--progress", "false"])
    lock = run / ".lock"
    t0 = time.time()
    while not (lock.exists() and f"pid {holder.pid}" in lock.read_text()):
        assert holder.poll() is None and time.time() - t0 < WAIT_S
        time.sleep(0.05)
    with pytest.raises(SystemExit, match=f"in use by pid {holder.pid}"):
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    holder.stderr.close()
    assert train_ppo.main(["--resume", str(run), "--progress", "false"]) == 0
    assert load_state(run / "final")["num_timesteps"] >= total


def test_a_session_killed_before_its_monitor_header_leaves_a_drawable_run(tmp_path):
    """A session killed between creating its monitor file and SB3's header row leaves the
    file empty: the learning curve (drawn at every run's end) reads the other sessions'."""
    from training.plumbing.plots import learning_curve

    (tmp_path / "0.monitor.csv").write_text(
        '#{"t_start": 0, "env_id": "x"}\nr,l,t,steps_completed\n1.5,10,0.1,0\n2.5,20,0.2,1\n'
    )
    (tmp_path / "512.monitor.csv").write_text("")
    (tmp_path / "1024.monitor.csv").write_text('#{"t_start": 0, "env_id": "x"}\n')
    learning_curve(tmp_path, tmp_path / "curve.png")
    assert (tmp_path / "curve.png").stat().st_size > 0
