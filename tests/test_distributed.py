"""Ray (the optional ``[distributed]`` extra): studies bit-identical to serial, clear errors.

The fast checks (a tiny Table 2 study on a local 2-CPU Ray instance, an unreachable address,
a failing task) run by default when Ray is installed; the sweep and RLlib runs are ``slow``.
"""

import csv
import gzip
import json
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from biped_constraint_env.simulator import PAPER_OPTIONS
from training.paper import table2_study
from training.paper.open_loop import TABLES
from training.plumbing.distributed import TasksFailed, init_ray, run_tasks, shutdown

ray = pytest.importorskip("ray")


@pytest.fixture
def local_ray():
    shutdown()
    init_ray(num_cpus=2)
    yield
    shutdown()
    assert not ray.is_initialized()


def _study(tmp_path, *flags):
    out = tmp_path / ("ray" if flags else "serial")
    argv = ["--postures", "2", "--seconds", "0.4", "--refine-iterations", "10"]
    assert table2_study.main([*argv, "--progress", "false", "--out-dir", str(out), *flags]) == 0
    (run,) = (out / "table2_study").iterdir()
    with gzip.open(run / "readings.csv.gz", "rt") as fh:
        return fh.read(), json.loads((run / "summary.json").read_text())


def test_table2_study_on_ray_equals_serial(tmp_path, local_ray):
    serial = _study(tmp_path)
    on_ray = _study(tmp_path, "--ray")
    assert serial[0].count("\n") == 24 * 64 + 1  # 24 option sets x 32 signs x 2 postures
    assert on_ray == serial


def test_open_loop_population_on_ray_equals_serial(local_ray):
    from training.paper.optimize_open_loop import OptimiseConfig, score_population

    X = np.random.default_rng(0).normal(0, 30, (10, 25))
    X[:, 20:] = X[:, 20:] / 100
    serial = score_population(X, OptimiseConfig(seconds=0.5))
    on_ray = score_population(X, OptimiseConfig(seconds=0.5, ray=True))  # 2 chunks of 5
    assert all(np.array_equal(a, b) for a, b in zip(serial, on_ray, strict=True))


def test_failed_task_named_with_its_arguments_others_kept(local_ray):
    # a function the workers import by name (a test module's own cannot be): bad durations fail
    table, posture = TABLES["table2"][None], np.zeros((1, 6))
    jobs = [(table, posture, PAPER_OPTIONS, s) for s in (0.04, -1.0, 0.04, np.nan)]
    with pytest.raises(TasksFailed) as e:
        run_tasks(table2_study.run_batch, jobs, use_ray=True)
    kept = e.value.results
    assert kept[1] is None and kept[3] is None
    assert all(np.array_equal(a, b) for a, b in zip(kept[0], kept[2], strict=True))
    assert [i for i, _, _ in e.value.failures] == [1, 3]
    assert "task 1 (array(1, 4, 5) float64, array(1, 6) float64, SimOptions(" in str(e.value)
    assert "-1.0) failed: ValueError: seconds must be" in str(e.value)


def test_serial_failures_reported_the_same_way():
    with pytest.raises(TasksFailed) as e:
        run_tasks(np.linalg.inv, [(np.eye(2),), (np.zeros((3, 3)),)])
    assert np.array_equal(e.value.results[0], np.eye(2)) and e.value.results[1] is None
    assert "task 1 (array(3, 3) float64) failed: LinAlgError" in str(e.value)


def test_unreachable_address_fails_fast_and_names_it():
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"127.0.0.1:{port}"
    t0 = time.monotonic()
    with pytest.raises(ConnectionError, match=address):
        run_tasks(np.sqrt, [(1.0,)], ray_address=address)
    assert time.monotonic() - t0 < 30  # seconds, not Ray's minute of retries
    assert not ray.is_initialized()
    with pytest.raises(ValueError, match="HOST:PORT"):
        init_ray("not-an-address")


def test_study_command_stops_at_a_bad_address_before_any_work(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{s.getsockname()[1]}"
    with pytest.raises(SystemExit, match=f"error: no Ray cluster reachable at '{address}'"):
        table2_study.main(["--ray-address", address, "--out-dir", str(tmp_path)])
    assert not any(tmp_path.iterdir())  # no run directory started


@pytest.mark.slow
def test_sweep_runs_two_trials_to_completion(tmp_path):
    from training.ppo import sweep

    tiny = [
        "total_timesteps=256",
        "n_envs=2",
        "n_steps=128",
        "batch_size=64",
        "n_epochs=1",
        "eval_freq=100000",
        "checkpoint_freq=100000",
    ]
    argv = ["--config", "training/configs/ppo_scratch.toml", "--seeds", "0", "1"]
    # a trial holding 2 CPUs may step its env on 2 numba threads (Ray's workers get 1 else)
    argv += ["--set", *tiny, "env_threads=2", "--cpus-per-trial", "2"]
    argv += ["--eval-episodes", "1", "--num-cpus", "2", "--out-dir", str(tmp_path)]
    assert sweep.main(argv) == 0
    assert not ray.is_initialized()
    with open(tmp_path / "sweep_ppo_scratch" / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["seed"] for r in rows] == ["0", "1"]
    for r in rows:
        assert float(r["steps_mean"]) >= 0 and float(r["train_wall_s"]) > 0
        assert (Path(r["run_dir"]) / "final" / "policy.safetensors").is_file()  # its checkpoint


@pytest.mark.slow
def test_readme_sweep_command_runs_every_trial(tmp_path):
    """The README's sweep command, as written (from the repository root, where the config's
    teacher gains are found), with a small budget added by --set."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    readme = (root / "README.md").read_text()
    command = "python -m training.ppo.sweep --config training/configs/ppo_walker.toml --seeds 0 1 2"
    assert command in readme
    small = ["bc_episodes0=1", "bc_periods0=40", "bc_rounds=0", "bc_grad_steps=20"]
    small += ["total_timesteps=256", "n_envs=2", "n_steps=128", "batch_size=64", "n_epochs=1"]
    small += ["eval_freq=100000", "checkpoint_freq=100000"]
    argv = [sys.executable, *command.split()[1:], "--set", *small]
    argv += ["--eval-episodes", "1", "--num-cpus", "2", "--out-dir", str(tmp_path)]
    proc = subprocess.run(argv, cwd=root, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    with open(tmp_path / "sweep_ppo_walker" / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["seed"] for r in rows] == ["0", "1", "2"]
    assert all("error" not in r or not r["error"] for r in rows), rows


@pytest.mark.slow
def test_rllib_example_trains_one_iteration(capsys):
    from training.plumbing import rllib_example

    assert rllib_example.main(["--iterations", "1", "--env-runners", "2", "--batch", "250"]) == 0
    assert "iteration 0: 250" in capsys.readouterr().out
    assert not ray.is_initialized()


def test_sweep_rejects_unknown_settings(tmp_path):
    from training.ppo import sweep

    base = ["--config", "training/configs/ppo_scratch.toml", "--out-dir", str(tmp_path)]
    for bad in (["--set", "no_such_field=1"], ["--grid", "seed=1,2"], ["--set", "gamma"]):
        with pytest.raises(SystemExit):
            sweep.main(base + bad)
    assert not ray.is_initialized()
