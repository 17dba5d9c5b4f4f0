"""Every command writes only its own output (docs/policy_files.md, "What a command touches").

Each case plants what a hostile run directory or a careless ``--out`` would hold (links to a
victim file outside, FIFOs, foreign folders, crafted counters) and checks that the command
refuses in one line (a ``SystemExit`` of status 2) or handles it safely, and that the victim
is unchanged and nothing outside the named output was created, appended to or deleted.
"""

from __future__ import annotations

import ast
import csv
import errno
import json
import math
import os
import shutil
import signal
import struct
import subprocess
import sys
import threading
import time
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
from subprocs import COMMANDS, start

from training.evaluation import evaluate
from training.plumbing.outputs import MARKER, OutDir, RunLock, command_output, write_file
from training.plumbing.safe_files import UntrustedFileError, read_npz
from training.ppo import train as train_ppo
from training.ppo.policy_io import (
    NORMALIZER_FILE,
    OPTIMIZER_FILE,
    STATE_FILE,
    load_policy,
    load_state,
    write_manifest,
)

ROOT = Path(__file__).resolve().parents[1]
SCRATCH = ROOT / "policies" / "ppo_gait_50hz"  # a committed policy
SMALL = ["--n-envs", "2", "--n-steps", "128", "--batch-size", "128", "--n-epochs", "1"]
SMALL += ["--eval-episodes", "1", "--progress", "false"]
VICTIM_TEXT = "precious\n"
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_NUM_THREADS": "1"}


@pytest.fixture
def victim(tmp_path):
    """A file outside every output, whose bytes must never change."""
    path = tmp_path / "outside" / "victim.txt"
    path.parent.mkdir()
    path.write_text(VICTIM_TEXT)
    return path


def _untouched(victim: Path) -> None:
    assert victim.read_text() == VICTIM_TEXT
    assert sorted(p.name for p in victim.parent.iterdir()) == ["victim.txt"]


def _one_line_refusal(excinfo, *words: str) -> None:
    msg = str(excinfo.value)
    assert excinfo.value.code == 2, msg
    assert "\n" not in msg and "Traceback" not in msg, msg
    for w in words:
        assert w in msg, msg


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    """A small finished run with a checkpoint (the thing a resume reads)."""
    out = tmp_path_factory.mktemp("trained")
    args = SMALL + ["--out-dir", str(out), "--total-timesteps", "512", "--checkpoint-freq", "256"]
    assert train_ppo.main(args + ["--eval-freq", "256"]) == 0
    (run,) = (out / "train_ppo").iterdir()
    return run


@pytest.fixture
def run(trained_run, tmp_path):
    """A copy of the small run to tamper with."""
    dst = tmp_path / "run"
    shutil.copytree(trained_run, dst)
    (dst / ".lock").unlink(missing_ok=True)
    return dst


# ------------------------------------------------------------------ 1, 3, 8: resume
def test_resume_never_writes_through_a_planted_config_tmp_link(run, victim):
    """Finding 1: ``RUN/config.toml.tmp`` -> victim; the README's extend command."""
    (run / "config.toml.tmp").symlink_to(victim)
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--total-timesteps", "1024", "--progress", "false"])
    _one_line_refusal(e, "config.toml.tmp", "symlink")
    _untouched(victim)


@pytest.mark.parametrize(
    "plant",
    [
        "checkpoints",  # the whole checkpoint folder linked outside
        "training_time.txt",
        "eval.csv",
        "figures",
        "tb",
        "512.monitor.csv",  # a dangling link where the next session's monitor goes
        "checkpoints/latest/policy.safetensors",
    ],
)
def test_resume_refuses_a_link_anywhere_in_the_run(run, victim, plant):
    """Finding 3: every link in the run is refused before anything is read or written."""
    target = run / plant
    if target.is_dir():
        shutil.rmtree(target)
    else:
        target.unlink(missing_ok=True)
    if plant.endswith("monitor.csv"):
        target.symlink_to(victim.parent / "created_by_the_monitor.csv")  # dangling
    elif plant in ("checkpoints", "figures", "tb"):
        target.symlink_to(victim.parent)
    else:
        target.symlink_to(victim)
    before = sorted(str(p.relative_to(run)) for p in run.rglob("*"))
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--total-timesteps", "1024", "--progress", "false"])
    _one_line_refusal(e, "symlink")
    _untouched(victim)
    after = sorted(str(p.relative_to(run)) for p in run.rglob("*"))
    assert set(after) - set(before) <= {".lock"}  # nothing else written


@pytest.mark.parametrize("kind", ["fifo", "dir", "link", "hardlink"])
def test_resume_refuses_an_odd_lock_or_file(run, victim, kind):
    lock = run / ".lock"
    if kind == "fifo":
        os.mkfifo(lock)
    elif kind == "dir":
        lock.mkdir()
    elif kind == "link":
        lock.symlink_to(victim)
    else:  # a hard link to the victim (same file system): appending would change it
        os.link(victim, run / "training_time2.txt")
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, ".lock" if kind != "hardlink" else "hard links")
    _untouched(victim) if kind != "hardlink" else None
    assert victim.read_text() == VICTIM_TEXT


def test_a_refused_second_writer_changes_nothing(run):
    """Finding 8: the lock comes first, so a refused resume has not rewritten config.toml."""
    before = (run / "config.toml").read_bytes()
    with OutDir.open(run) as d, RunLock(d):
        with pytest.raises(SystemExit) as e:
            train_ppo.main(["--resume", str(run), "--total-timesteps", "99999"])
        _one_line_refusal(e, "in use by pid")
    assert (run / "config.toml").read_bytes() == before


def test_a_monitor_linked_to_dev_zero_is_refused(run):
    (run / "0.monitor.csv").unlink()
    (run / "0.monitor.csv").symlink_to("/dev/zero")
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, "0.monitor.csv", "symlink")


# ------------------------------------------------------------------ 6, 12: counters and state
def _reseal(where: Path) -> None:
    write_manifest(where)


def _state(run: Path, **changes) -> None:
    path = run / "checkpoints" / "latest" / STATE_FILE
    st = json.loads(path.read_text())
    st.update(changes)
    path.write_text(json.dumps(st))
    _reseal(path.parent)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"num_timesteps": 10**23}, "num_timesteps must be an integer in"),
        ({"num_timesteps": -1}, "num_timesteps must be an integer in"),
        ({"wall_s": -5}, "wall_s"),
    ],
)
def test_resume_checks_the_checkpoints_counters(run, changes, match):
    _state(run, **changes)
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, match)


def test_a_nan_score_is_refused(run):
    path = run / "checkpoints" / "latest" / STATE_FILE
    path.write_text(path.read_text().replace('"best": ', '"best": NaN, "x": '))
    _reseal(path.parent)
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, "not valid JSON", "NaN")


def _optimizer_meta(run: Path, edit) -> None:
    from safetensors import safe_open
    from safetensors.torch import load_file, save_file

    path = run / "checkpoints" / "latest" / OPTIMIZER_FILE
    with safe_open(str(path), framework="pt") as fh:
        meta = fh.metadata()
    tensors = load_file(str(path))
    groups = json.loads(meta["param_groups"])
    edit(groups, tensors)
    meta["param_groups"] = json.dumps(groups)
    save_file(tensors, str(path), metadata=meta)
    _reseal(path.parent)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda g, t: g[0].update(maximize=True), "maximize"),
        (lambda g, t: g[0].update(eps=-1.0), "eps"),
        (lambda g, t: g[0].update(lr=5.0), "lr must be in"),
        (
            lambda g, t: t.update({k: -abs(v) - 1 for k, v in t.items() if "exp_avg_sq" in k}),
            "negative second moment",
        ),
    ],
)
def test_crafted_optimizer_state_is_refused(run, edit, match):
    """Finding 6: ``maximize = true`` would make Adam ascend; ``eps = -1`` divide by ~0."""
    _optimizer_meta(run, edit)
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, match)


@pytest.mark.parametrize(("key", "value"), [("ret_var", -1.0), ("ret_count", -5.0)])
def test_a_negative_return_statistic_is_refused(run, key, value):
    path = run / "checkpoints" / "latest" / NORMALIZER_FILE
    with np.load(path) as z:
        d = {k: z[k] for k in z.files}
    d[key] = np.float64(value)
    np.savez(path, **d)
    _reseal(path.parent)
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, f"{key} is negative")


def test_imitation_counters_are_checked(tmp_path):
    """Finding 6: an imitation checkpoint's round is range-checked (round = -10^6 looped)."""
    from training.ppo import warm_start
    from training.ppo.config import PPOConfig

    cfg = PPOConfig(teacher="model", bc_rounds=3)
    where = tmp_path / "ckpt"
    where.mkdir()
    (where / STATE_FILE).write_text(json.dumps({"round": -1000000, "seed": 1, "rows": [],
                                                "rng": {}, "wall_s": 0}))  # fmt: skip
    write_manifest(where)
    with pytest.raises(UntrustedFileError, match="round must be an integer in"):
        warm_start.resume_imitation(cfg, where, None, np.random.default_rng(0))


# ------------------------------------------------------------------ 10: kills and eval rows
def _start(args: list[str]) -> subprocess.Popen:
    return start("training.ppo.train", args)


@pytest.mark.parametrize("module", COMMANDS)
def test_ctrl_c_while_a_command_starts_is_one_line(module):
    """A Ctrl-C during a command's imports (before its ``main``): one line, no traceback.

    The command's package imports the hook first (checked in its ``__init__``), so the hook is
    in place before the command module's own imports; in a program started as ``python -m``
    on one of the packages' modules, it shows an uncaught KeyboardInterrupt as one line.
    """
    package = module.split(".")[0]
    tree = ast.parse((ROOT / package / "__init__.py").read_text())
    first = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    assert isinstance(first[0], ast.Import)
    assert first[0].names[0].name == "training.plumbing.interrupts"
    code = (f"import sys; sys.orig_argv = [sys.executable, '-m', {module!r}]; import {package}; "
            "raise KeyboardInterrupt")  # fmt: skip
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)  # fmt: skip
    assert p.returncode != 0 and "Traceback" not in p.stderr, p.stderr
    name = module.rsplit(".", 1)[-1]
    assert p.stderr.strip() == f"{name}: interrupted while starting; nothing was written"


def test_ctrl_c_hook_leaves_a_library_user_alone():
    """Imported by another program (``python -c``, pytest, ``python -m`` on another package),
    the hook changes nothing: a KeyboardInterrupt keeps its traceback."""
    from training.plumbing.interrupts import command_name

    assert command_name(["python", "-m", "training.ppo.train", "--seed", "1"]) == "train"
    assert command_name(["python", "-X", "utf8", "-m", "benchmarks.bench_env"]) == "bench_env"
    assert command_name(["python", "-m", "pytest", "-m", "training.x"]) is None
    assert command_name(["python", "-c", "import training"]) is None
    assert command_name(["python", "-m"]) is None
    assert command_name(["python", "-W", "error", "-mtraining.evaluate"]) == "evaluate"
    assert command_name(["python", "-c", "pass", "-m", "training.ppo.train"]) is None  # argv of -c
    assert command_name(["python", "script.py", "-m", "training.ppo.train"]) is None
    for code in ("import training; raise KeyboardInterrupt",
                 "import sys; sys.orig_argv = [sys.executable, '-m', 'pytest']; import training; "
                 "raise KeyboardInterrupt"):  # fmt: skip
        p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                           text=True, timeout=120)  # fmt: skip
        assert "Traceback" in p.stderr, p.stderr


def test_a_kill_campaign_leaves_exactly_the_final_runs_evaluations(tmp_path):
    """Ten random SIGKILL / SIGINT of one run, each resumed: every evaluation once, in order."""
    rng = np.random.default_rng(1)
    total, every = 12_288, 1024
    args = SMALL + ["--out-dir", str(tmp_path), "--total-timesteps", str(total)]
    args += ["--checkpoint-freq", "256", "--eval-freq", str(every)]
    proc = _start(args)
    t0 = time.time()
    while not list(tmp_path.glob("train_ppo/*/checkpoints/latest/" + STATE_FILE)):
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        assert time.time() - t0 < 300
        time.sleep(0.05)
    (run,) = (tmp_path / "train_ppo").iterdir()
    kills = 0
    while kills < 10:
        time.sleep(rng.uniform(0.5, 4.0))
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL if rng.random() < 0.5 else signal.SIGINT)
            kills += 1
        proc.wait()
        err = proc.stderr.read().decode()
        proc.stderr.close()
        assert "Traceback" not in err, err[-3000:]
        proc = _start(["--resume", str(run), "--progress", "false"])
    proc.wait(timeout=600)
    proc.stderr.close()
    if (
        load_state(run / "checkpoints" / "latest")["num_timesteps"] < total
        or not (run / "final").exists()
    ):
        assert train_ppo.main(["--resume", str(run), "--progress", "false"]) == 0
    with open(run / "eval.csv") as fh:
        steps = [int(r["env_steps"]) for r in csv.DictReader(fh)]
    assert steps == list(range(every, total + 1, every))


# ------------------------------------------------------------------ 2, 7: --out folders
def test_evaluate_out_never_deletes_a_policy_folder(tmp_path):
    """Finding 2: ``--out policies`` removed all six committed policies."""
    policies = tmp_path / "policies"
    shutil.copytree(SCRATCH, policies / "ppo_gait_50hz", ignore=shutil.ignore_patterns("fig*"))
    before = sorted(str(p) for p in policies.rglob("*"))
    for out in (policies, policies / "ppo_gait_50hz", policies / "ppo_gait_50hz" / "final"):
        with pytest.raises(SystemExit) as e:
            evaluate.main([str(policies / "ppo_gait_50hz"), "--episodes", "1", "--out",
                           str(out)])  # fmt: skip
        _one_line_refusal(e, "no command of this package wrote there")
    assert sorted(str(p) for p in policies.rglob("*")) == before


def test_an_output_replaces_only_its_own_files(tmp_path, victim):
    out = tmp_path / "out"
    with command_output(out, "cmd_a") as co:
        co.dir().write("a.json", "1")
        co.dir("figures").write("a.png", "x")
    with command_output(out, "cmd_b") as co:  # another command beside it
        co.dir().write("b.json", "2")
    with command_output(out, "cmd_a") as co:  # the same command again: replaces its own
        co.dir().write("a.json", "3")
    assert (out / "a.json").read_text() == "3" and (out / "b.json").read_text() == "2"
    assert not (out / "figures" / "a.png").exists()  # its stale file of the earlier run
    (out / "user_notes.txt").write_text("mine")
    with pytest.raises(UntrustedFileError, match="user_notes.txt"), command_output(out, "cmd_a"):
        pass
    (out / "user_notes.txt").unlink()
    (out / "b.json").unlink()
    (out / "b.json").symlink_to(victim)
    with pytest.raises(UntrustedFileError, match="symlink"), command_output(out, "cmd_b"):
        pass
    _untouched(victim)


def test_an_interrupted_command_leaves_no_partial_file(tmp_path):
    """Finding 7: a kill left a 0-byte PNG beside the old JSON; staging makes it all or none."""
    out = tmp_path / "out"
    with command_output(out, "bench") as co:
        co.dir().write("result.json", "old")
    with pytest.raises(KeyboardInterrupt), command_output(out, "bench") as co:
        co.dir().write("figure.png", "half")
        raise KeyboardInterrupt
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "result.json"]
    assert (out / "result.json").read_text() == "old"


DROPPED_CTRL_C = """
import gc, os, signal, sys
sys.orig_argv = [sys.executable, "-m", "training.evaluation.evaluate"]
import training
from training.plumbing.outputs import command_output


class Finaliser:
    def __del__(self):  # Ctrl-C arrives while Python runs a finaliser: it drops the exception
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):
            pass


with command_output(sys.argv[1], "evaluate") as co:
    co.dir().write("evaluation.json", "new")
    Finaliser()
    gc.collect()
    print("the work went on", flush=True)
"""


def test_a_ctrl_c_that_python_drops_still_writes_nothing(tmp_path):
    """Ctrl-C raised inside a finaliser is dropped by Python ("Exception ignored"); the command
    records it, and its output is not moved in as if the work had finished."""
    out = tmp_path / "out"
    with command_output(out, "evaluate") as co:
        co.dir().write("evaluation.json", "old")
    p = subprocess.run([sys.executable, "-c", DROPPED_CTRL_C, str(out)], cwd=tmp_path,
                       capture_output=True, text=True, timeout=120, env=ENV)  # fmt: skip
    assert "the work went on" in p.stdout and "Exception ignored" in p.stderr, p.stderr
    assert p.returncode != 0
    assert (out / "evaluation.json").read_text() == "old"
    assert sorted(q.name for q in out.iterdir()) == [MARKER, "evaluation.json"]


@pytest.mark.parametrize("module", ["benchmarks.failure_modes", "benchmarks.accuracy"])
def test_benchmarks_refuse_a_foreign_or_linked_out(tmp_path, victim, module):
    link = tmp_path / "link"
    link.symlink_to(victim.parent)
    for out in (link, victim.parent):
        p = subprocess.run([sys.executable, "-m", module, "--out", str(out)], cwd=tmp_path,
                           capture_output=True, text=True, timeout=300, env=ENV)  # fmt: skip
        assert p.returncode == 2, p.stderr[-2000:]
        assert "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) <= 2
    _untouched(victim)


def test_write_file_replaces_a_link_instead_of_following_it(tmp_path, victim):
    (tmp_path / "compare.json").symlink_to(victim)
    write_file(tmp_path / "compare.json", "{}")
    assert (tmp_path / "compare.json").read_text() == "{}" and not (
        tmp_path / "compare.json"
    ).is_symlink()
    _untouched(victim)


# ------------------------------------------------------------------ 4, 11: bounded parsing
def test_a_bzip2_npy_header_bomb_is_refused_in_bounded_memory(tmp_path):
    """Finding 4: a 3.7 KB normalizer.npz whose v2 header claims 1 GiB took 2.5 GB."""
    raw = b"\x93NUMPY\x02\x00" + struct.pack("<I", 1 << 30) + b" " * (1 << 24)
    path = tmp_path / "normalizer.npz"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_BZIP2) as zf:
        zf.writestr("obs_mean.npy", raw)
    assert path.stat().st_size < 20_000
    tracemalloc.start()
    with pytest.raises(UntrustedFileError, match="oddly compressed|header of"):
        read_npz(path, {"obs_mean": ((None,), "f")})
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 50 << 20


def test_a_deflated_npy_header_bomb_is_refused_by_its_length(tmp_path):
    raw = b"\x93NUMPY\x02\x00" + struct.pack("<I", 1 << 30) + b" " * (1 << 22)
    path = tmp_path / "x.npz"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("a.npy", raw)
    with pytest.raises(UntrustedFileError, match="a header of 1073741824 bytes"):
        read_npz(path, {"a": ((None,), "f")})


def test_an_encrypted_member_is_refused(tmp_path):
    path = tmp_path / "x.npz"
    np.savez(path, a=np.zeros(2))
    data = bytearray(path.read_bytes())
    for sig in (b"PK\x03\x04", b"PK\x01\x02"):  # the flag bits of both headers
        i = data.find(sig)
        off = i + (6 if sig == b"PK\x03\x04" else 8)
        data[off] |= 1
    path.write_bytes(bytes(data))
    with pytest.raises(UntrustedFileError, match="encrypted|not a valid npz"):
        read_npz(path, {"a": ((2,), "f")})


def test_a_safetensors_file_the_rust_parser_refuses_is_one_line(tmp_path, monkeypatch):
    """Whatever the Rust parser refuses after the Python header check passed is one line."""
    import safetensors.torch
    from safetensors import SafetensorError

    from training.plumbing.safe_files import load_safetensors

    def refuse(_data):
        raise SafetensorError("Error while deserializing header: InvalidHeader")

    monkeypatch.setattr(safetensors.torch, "load", refuse)
    header = json.dumps({"a": {"dtype": "F32", "shape": [1], "data_offsets": [0, 4]}}).encode()
    data = struct.pack("<Q", len(header)) + header + b"\0\0\0\0"
    with pytest.raises(UntrustedFileError, match="refused by the safetensors parser"):
        load_safetensors(tmp_path / "p.safetensors", data)
    header = b'{"a": {"dtype": "F32", "shape": [1], "data_offsets": [0.0, 4.0]}}'
    data = struct.pack("<Q", len(header)) + header + b"\0\0\0\0"
    with pytest.raises(UntrustedFileError, match="malformed header entry"):
        load_safetensors(tmp_path / "p.safetensors", data)


@pytest.mark.parametrize(
    ("toml", "match"),
    [
        ("learning_rate = 1" + "0" * 400 + ".0\n", "must be finite"),
        ("total_timesteps = 1" + "0" * 400 + "\n", "64-bit integer"),
        ("x = " + "[" * 3000 + "]" * 3000 + "\n", "nested too deeply"),
        ('[env]\nrender_mode = "human"\n', "render_mode is not a setting"),
        ("[env]\ndt = 1e-9\n", "dt must be"),
        ("[env]\nphysics = {substeps = 100000}\n", "substeps must be at most"),
        ("[env]\nphysics = {step_tol = 1e-10}\n", "step_tol must be at least"),
        ('[env]\naction = {kind = "pd", dt = 1e-9}\n', "pd_dt must be"),
        # a value of the wrong TOML type (a string was taken for stop_evals = "2")
        ('stop_evals = "2"\n', "stop_evals must be an integer, got '2'"),
        ('learning_rate = "3e-4"\n', "learning_rate must be a number"),
        ("use_sde = 1\n", "use_sde must be true or false"),
        ('net_arch = ["128", "128"]\n', "net_arch must be a list"),
        ("activation = 3\n", "activation must be a string"),
    ],
)
def test_costly_or_malformed_configs_are_one_line(tmp_path, toml, match):
    """Findings 5 and 11: a config may not set days of work, nor crash the parser; nor pass a
    value of the wrong type (flags are text and stay converted: see the last test here)."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--config", str(cfg), "--out-dir", str(tmp_path / "runs")])
    _one_line_refusal(e, match)
    assert not (tmp_path / "runs").exists()


def test_a_flag_is_text_converted_to_its_settings_type():
    from training.plumbing.common import parse_config
    from training.ppo.config import PPOConfig

    cfg = parse_config(PPOConfig, ["--stop-evals", "2", "--learning-rate", "3e-4"], "t")
    assert cfg.stop_evals == 2 and cfg.learning_rate == 3e-4


def test_the_cli_and_the_config_share_the_control_period_bound():
    from biped_constraint_env.tasks import MIN_DT_S

    with pytest.raises(SystemExit) as e:
        evaluate.main([str(SCRATCH), "--dt", str(MIN_DT_S / 2)])
    _one_line_refusal(e, "--dt")


@pytest.mark.parametrize(
    "argv",
    [
        ["training.evaluation.compare", str(SCRATCH), "--which", "nope"],
        [
            "training.ppo.policy_io",
            "import-sb3",
            "missing.zip",
            "--vecnormalize",
            "m.pkl",
            "--out",
            "o",
        ],
        ["benchmarks.bench_core", "--n", "0"],
        ["training.evaluation.evaluate", "no/such/run"],
        ["training.ppo.train", "--resume", "no/such/run"],
    ],
)
def test_refusals_are_one_line_with_status_2(tmp_path, argv):
    p = subprocess.run([sys.executable, "-m", *argv], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300, env=ENV)  # fmt: skip
    assert p.returncode == 2, p.stderr[-2000:]
    lines = [ln for ln in p.stderr.splitlines() if "error" in ln]
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr[-2000:]
    assert list(tmp_path.iterdir()) == []


def _can_mount(tmp_path: Path) -> bool:
    probe = tmp_path / "probe"
    probe.mkdir()
    ok = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(probe)],
                        capture_output=True).returncode == 0  # fmt: skip
    if ok:
        subprocess.run(["umount", str(probe)], check=True)
    probe.rmdir()
    return ok


@pytest.mark.parametrize("how", ["full", "read-only"])
def test_a_full_or_read_only_disk_is_one_line(tmp_path, how):
    if not shutil.which("mount") or not _can_mount(tmp_path):
        pytest.skip("this machine cannot mount a tmpfs here (needs root and mount rights)")
    disk = tmp_path / "disk"
    disk.mkdir()
    opts = "size=16k" if how == "full" else "size=1m,ro"
    subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(disk)], check=True)
    try:
        p = subprocess.run(
            [sys.executable, "-m", "training.evaluation.compare", str(SCRATCH), "--which", "final",
             "--episodes", "1", "--out", str(disk / "rows.json"), "--curves",
             str(disk / "curves.png")],
            cwd=tmp_path, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert p.returncode == 2, p.stderr[-2000:]
        assert "Traceback" not in p.stderr
        assert ("disk is full" if how == "full" else "read-only") in p.stderr.lower()
        assert [x.name for x in disk.iterdir()] == []  # no 0-byte .partial left
    finally:
        subprocess.run(["umount", str(disk)], check=True)


# ------------------------------------------------------------------ 9: a load during a replacement
def test_a_load_during_a_replacement_never_mixes_two_snapshots(tmp_path):
    """Finding 9: a snapshot replaced while it loads gives the old files or the new ones."""
    import torch

    from training.ppo.policy_io import build_policy, read_config, save_snapshot

    run = tmp_path / "run"
    shutil.copytree(
        SCRATCH, run, ignore=shutil.ignore_patterns("figures", "best", "published.json")
    )
    cfg = read_config(run)
    policy = build_policy(cfg)

    class Norm:  # the VecNormalize fields save_normalizer reads
        def __init__(self, v):
            self.obs_rms = type(
                "R",
                (),
                {"mean": np.full(cfg.obs_dim(), v), "var": np.ones(cfg.obs_dim()), "count": 1.0},
            )()
            self.ret_rms = type("R", (), {"mean": 0.0, "var": 1.0, "count": 1.0})()
            self.norm_obs, self.norm_reward, self.clip_obs, self.clip_reward = (
                True,
                True,
                10.0,
                10.0,
            )
            self.gamma, self.epsilon = 0.99, 1e-8

    versions = []
    for v in (1.0, 2.0):
        with torch.no_grad():
            for p in policy.parameters():
                p.fill_(v)
        versions.append((policy.state_dict()["action_net.bias"][0].item(), Norm(v)))
        save_snapshot(run / f"v{int(v)}", policy, {"num_timesteps": int(v)}, Norm(v))
    stop = threading.Event()

    def writer():
        k = 0
        while not stop.is_set():
            shutil.rmtree(run / "final.tmp", ignore_errors=True)
            shutil.copytree(run / f"v{1 + k % 2}", run / "final.tmp")
            shutil.rmtree(run / "final.prev", ignore_errors=True)
            os.rename(run / "final", run / "final.prev")
            os.rename(run / "final.tmp", run / "final")
            k += 1

    shutil.rmtree(run / "final")
    shutil.copytree(run / "v1", run / "final")
    t = threading.Thread(target=writer)
    t.start()
    loads = 0
    try:
        t_end = time.time() + 8
        while time.time() < t_end:
            try:
                pol, norm, _, state = load_policy(run, "final")
            except (FileNotFoundError, UntrustedFileError):
                continue
            w = pol.state_dict()["action_net.bias"][0].item()
            assert w == state["num_timesteps"] == norm.mean[0], (w, state, norm.mean[0])
            loads += 1
    finally:
        stop.set()
        t.join()
    assert loads > 20


# ------------------------------------------------------------------ 12-16: the newcomer's path
def test_reset_takes_a_numpy_integer_seed():
    import gymnasium as gym

    env = gym.make("ConstrainedBiped-v0")
    a, _ = env.reset(seed=np.int64(5))
    b, _ = env.reset(seed=5)
    assert np.array_equal(a, b)


def test_the_documented_observation_noise_bound_holds():
    import gymnasium as gym

    gym.make("ConstrainedBiped-v0", perturbations={"obs_noise": (0.02, 50.0)})  # up to 100
    with pytest.raises(ValueError, match="obs_noise"):
        gym.make("ConstrainedBiped-v0", perturbations={"obs_noise": (0.02, 101.0)})


def test_outputs_are_standard_json(tmp_path):
    from training.ppo.policy_io import json_text

    text = json_text({"a": math.nan, "b": [-math.inf, 1.0], "c": np.float64(2.0)})
    assert json.loads(text, parse_constant=lambda c: pytest.fail(c)) == {
        "a": None,
        "b": [None, 1.0],
        "c": 2.0,
    }


def test_the_help_example_of_evaluate_runs(tmp_path, capsys):
    """Finding 13: ``--controller model:teacher_robust+start_rest --start rest`` crashed."""
    out = tmp_path / "ev"
    argv = ["--controller", "model:teacher_robust+start_rest", "--start", "rest",
            "--episodes", "2", "--out", str(out)]  # fmt: skip
    assert evaluate.main(argv) == 0
    text = capsys.readouterr().out
    assert "walk task" in text and "ConstrainedBiped-v0  task" not in text
    summary = json.loads((out / "evaluation.json").read_text())
    init = summary["results"][0]["initiation"]
    assert init["first_step_m_mean"] is None or math.isfinite(init["first_step_m_mean"])
    assert "(2/2)" in text or "(1/2)" in text or "(0/2)" in text  # counts, not a rounded %


def test_ctrl_c_before_the_first_snapshot_names_a_command_that_works(tmp_path, monkeypatch):
    """Finding 14: Ctrl-C before a snapshot said "--resume RUN", which is then refused."""

    def interrupt(*_a, **_k):
        raise KeyboardInterrupt

    monkeypatch.setattr(train_ppo, "training_env", interrupt)
    with pytest.raises(SystemExit) as e:
        train_ppo.main(SMALL + ["--out-dir", str(tmp_path), "--total-timesteps", "256"])
    assert e.value.code == 130
    (run,) = (tmp_path / "train_ppo").iterdir()
    assert "holds no snapshot yet" in train_ppo._interrupted()
    assert str(run) in train_ppo._interrupted()


def test_messages_cite_pages_that_exist():
    """Finding 16: messages and docstrings named README sections that do not exist."""
    import re

    bad = []
    for path in [*ROOT.glob("biped_constraint_env/*.py"), *ROOT.glob("training/**/*.py"),
                 *ROOT.glob("benchmarks/*.py")]:  # fmt: skip
        text = path.read_text()
        bad += [f"{path.name}: README, {m}" for m in re.findall(r"README, ([A-Z][\w ]+)", text)]
        bad += [
            f"{path.name}: {m}"
            for m in re.findall(r"docs/[\w./]+\.md", text)
            if not (ROOT / m).exists()
        ]
    assert bad == []


def test_expected_errnos_are_named():
    from training.plumbing.common import EXPECTED_ERRNOS

    assert {errno.ENOSPC, errno.EROFS, errno.EACCES} <= set(EXPECTED_ERRNOS)


# ------------------------------------------------------------------ the published snapshot
def test_a_run_publishes_its_selected_snapshot_and_evaluate_loads_it(trained_run, tmp_path):
    from training.ppo.policy_io import published_snapshot

    pub = json.loads((trained_run / "published.json").read_text())
    assert pub["snapshot"] == "best" and "selection" in pub["why"]
    assert published_snapshot(trained_run)[0] == "best"
    out = tmp_path / "ev"
    assert evaluate.main([str(trained_run), "--episodes", "1", "--out", str(out)]) == 0
    summary = json.loads((out / "evaluation.json").read_text())
    assert summary["which"] == "best" and summary["why"] == pub["why"]


@pytest.mark.parametrize("policy", sorted(p.name for p in (ROOT / "policies").iterdir()))
def test_every_committed_policy_publishes_the_snapshot_its_figures_are_of(policy):
    """The README's rows are of the snapshot in each policy's evaluation.json; evaluate's
    default loads the same one."""
    from training.ppo.policy_io import published_snapshot

    d = ROOT / "policies" / policy
    assert published_snapshot(d)[0] == json.loads((d / "evaluation.json").read_text())["which"]


def test_a_crafted_published_file_is_refused(tmp_path):
    from training.ppo.policy_io import published_snapshot

    run = tmp_path / "run"
    run.mkdir()
    for crafted in (
        '{"snapshot": "../../etc", "why": ""}',
        '{"snapshot": ["best"]}',
        '{"snapshot": {"best": 1}}',
        '{"snapshot": "best", "why": ["x"]}',
    ):
        (run / "published.json").write_text(crafted)  # a list: a traceback before (finding)
        with pytest.raises(UntrustedFileError, match="snapshot must be one of"):
            published_snapshot(run)


# ------------------------------------------------------------------ the stop rule
def _walking_evaluations(monkeypatch):
    """Every selection episode walks 25 steps (the evaluations, not the training, faked)."""

    def fake(act, env_kwargs, seeds, env_id="", **_kw):
        return [{"steps_completed": 25, "distance_m": 20.0, "return": 1.0,
                 "end": "time_limit"} for _ in seeds]  # fmt: skip

    from training.ppo import callbacks

    monkeypatch.setattr(callbacks, "run_episodes_batched", fake)


def test_a_run_stops_once_its_criterion_has_held_and_says_so(tmp_path, monkeypatch, capsys):
    _walking_evaluations(monkeypatch)
    args = SMALL + ["--out-dir", str(tmp_path), "--total-timesteps", "4096"]
    args += ["--eval-freq", "512", "--checkpoint-freq", "512", "--stop-min-steps", "20"]
    assert train_ppo.main(args) == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    n = load_state(run / "final")["num_timesteps"]
    assert 1024 <= n < 1024 + 256  # two evaluations (512, 1024), then the stop
    assert "[stop] 1024 env steps" in capsys.readouterr().out
    assert "stopped: every selection episode" in (run / "training_time.txt").read_text()
    assert "stopped" in json.loads((run / "published.json").read_text())["why"]
    # a resume of a stopped run trains no further, unless given a new total
    assert train_ppo.main(["--resume", str(run), "--progress", "false"]) == 0
    assert load_state(run / "final")["num_timesteps"] == n


def test_a_run_without_the_criterion_uses_its_budget(tmp_path, monkeypatch):
    _walking_evaluations(monkeypatch)
    args = SMALL + ["--out-dir", str(tmp_path), "--total-timesteps", "1536", "--eval-freq", "512"]
    assert train_ppo.main(args) == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    assert load_state(run / "final")["num_timesteps"] >= 1536
    assert "budget of 1536 env steps ended" in (run / "training_time.txt").read_text()


def test_a_confirmed_evaluation_stops_the_run_at_once_and_counts_every_episode(
    tmp_path, monkeypatch, capsys
):
    """stop_confirm_episodes: an evaluation whose episodes all walk runs the same network on
    the next selection seeds; with stop_evals 1 the run stops at that evaluation."""
    from training.ppo import callbacks
    from training.ppo.config import SELECTION_SEED_OFFSET

    seen = []

    def fake(act, env_kwargs, seeds, env_id="", **_kw):
        seen.append(list(seeds))
        return [{"steps_completed": 25, "distance_m": 20.0, "return": 1.0,
                 "end": "time_limit"} for _ in seeds]  # fmt: skip

    monkeypatch.setattr(callbacks, "run_episodes_batched", fake)
    args = SMALL + ["--out-dir", str(tmp_path), "--total-timesteps", "4096", "--eval-freq", "512"]
    args += ["--stop-min-steps", "20", "--stop-evals", "1", "--stop-confirm-episodes", "3"]
    assert train_ppo.main(args) == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    assert 512 <= load_state(run / "final")["num_timesteps"] < 512 + 256
    s = SELECTION_SEED_OFFSET
    assert seen == [[s], [s + 1, s + 2, s + 3]]  # the evaluation, then the next seeds
    with open(run / "eval.csv") as fh:
        (row,) = list(csv.DictReader(fh))
    assert json.loads(row["reasons"]) == {"time_limit": 4}
    out = capsys.readouterr().out
    assert "[stop] 512 env steps" in out and "(1 + 3 episodes of the same network)" in out
    why = json.loads((run / "published.json").read_text())["why"]
    assert "3 more where all met the stop criterion" in why and "at 512 env steps" in why


def test_a_failed_confirmation_neither_stops_nor_scores_the_evaluation_as_walking(
    tmp_path, monkeypatch
):
    from training.ppo import callbacks
    from training.ppo.config import SELECTION_SEED_OFFSET

    def fake(act, env_kwargs, seeds, env_id="", **_kw):  # the confirmation's seeds fall
        return [{"steps_completed": 25 if k == SELECTION_SEED_OFFSET else 2, "distance_m": 1.0,
                 "return": 1.0, "end": "time_limit"} for k in seeds]  # fmt: skip

    monkeypatch.setattr(callbacks, "run_episodes_batched", fake)
    args = SMALL + ["--out-dir", str(tmp_path), "--total-timesteps", "1536", "--eval-freq", "512"]
    args += ["--stop-min-steps", "20", "--stop-evals", "1", "--stop-confirm-episodes", "2"]
    assert train_ppo.main(args) == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    assert load_state(run / "final")["num_timesteps"] >= 1536
    with open(run / "eval.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and {r["steps_min"] for r in rows} == {"2"}
    assert load_state(run / "best")["score"] < 20
    assert "budget of 1536 env steps ended" in (run / "training_time.txt").read_text()


# ------------------------------------------------------------------ a second review's findings
def test_a_refused_out_keeps_the_users_staging_named_folder(tmp_path):
    out = tmp_path / "userdir"
    (out / ".staging-notes").mkdir(parents=True)
    (out / ".staging-notes" / "thesis.txt").write_text("precious")
    (out / "notes.txt").write_text("mine")
    with pytest.raises(UntrustedFileError), command_output(out, "failure_modes"):
        pass
    assert (out / ".staging-notes" / "thesis.txt").read_text() == "precious"


def test_a_dead_commands_staging_is_cleaned_and_a_live_ones_kept(tmp_path):
    out = tmp_path / "out"
    with command_output(out, "cmd") as co:
        co.dir().write("a.txt", "1")
    dead = out / ".staging-cmd-999999999-0123abcd"
    live = out / f".staging-cmd-{os.getpid()}-0123abcd"
    dead.mkdir()
    live.mkdir()
    with command_output(out, "cmd") as co:
        co.dir().write("a.txt", "2")
    assert not dead.exists() and live.exists()


def _policy_copy(tmp_path: Path, name: str = "ppo_gait_50hz") -> Path:
    run = tmp_path / "p"
    shutil.copytree(ROOT / "policies" / name, run, ignore=shutil.ignore_patterns("figures"))
    return run


def _evaluate_refused(run: Path, tmp_path: Path, *words: str, extra=()) -> None:
    with pytest.raises(SystemExit) as e:
        evaluate.main([str(run), "--episodes", "1", "--out", str(tmp_path / "o"), *extra])
    _one_line_refusal(e, *words)


def test_a_manifest_naming_an_unknown_file_is_refused(tmp_path):
    run = _policy_copy(tmp_path)
    for name in ("a\x00b", "", "pad0.bin"):
        m = json.loads((run / "final" / "manifest.json").read_text())
        m[name] = {"bytes": 1, "sha256": "x"}
        (run / "final" / "manifest.json").write_text(json.dumps(m))
        _evaluate_refused(run, tmp_path, "not a snapshot file", extra=["--which", "final"])
        m.pop(name)
        (run / "final" / "manifest.json").write_text(json.dumps(m))


def test_a_safetensors_shape_of_many_dimensions_is_refused(tmp_path):
    from training.plumbing.safe_files import safetensors_header

    h = json.dumps({"a": {"dtype": "F32", "shape": [2**39] * 30, "data_offsets": [0, 4]}})
    data = struct.pack("<Q", len(h)) + h.encode() + b"\0" * 4
    with pytest.raises(UntrustedFileError, match="malformed header entry"):
        safetensors_header(tmp_path / "x", data=data)


def test_a_huge_integer_score_is_one_line(tmp_path):
    run = _policy_copy(tmp_path)
    (run / "final" / STATE_FILE).write_text('{"num_timesteps": 1, "score": 18446744073709551616}')
    write_manifest(run / "final")
    _evaluate_refused(run, tmp_path, "score must be a number in", extra=["--which", "final"])


def test_an_optimizer_tensor_of_another_name_is_one_line(run):
    def add(groups, tensors):
        import torch

        tensors["x"] = torch.zeros(1)

    _optimizer_meta(run, add)
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, "not this optimizer's state")


@pytest.mark.parametrize("name", ["tb/PPO_1\u00b2", "tb/events", "\u00b2.monitor.csv"])
def test_log_names_the_run_does_not_write_are_refused(run, name):
    target = run / name
    target.parent.mkdir(exist_ok=True)
    if name.startswith("tb/"):
        target.mkdir()
    else:
        target.write_text("")
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--total-timesteps", "1024", "--progress", "false"])
    _one_line_refusal(e, "this run writes")


def test_an_imitation_log_of_deep_or_odd_values_is_refused(tmp_path):
    from training.plumbing.plots import _int_list

    for text in ("[" * 50_000 + "]" * 50_000, '{"a": 1}', "[1.5]", "[]"):
        with pytest.raises((ValueError, RecursionError)):
            _int_list(text)
    assert _int_list("[3, 4]") == [3, 4]


def test_a_controller_spec_of_three_parts_is_refused(tmp_path, monkeypatch):
    run = _policy_copy(tmp_path, "ppo_walker")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "start_rest+start_rest").write_text("{}")  # a file the spec would open
    text = (run / "config.toml").read_text().splitlines()
    text = [ln for ln in text if not ln.startswith("base_controller")]
    text.insert(0, 'base_controller = "model:teacher_robust+start_rest+start_rest"')
    (run / "config.toml").write_text("\n".join(text) + "\n")
    _evaluate_refused(run, tmp_path, "model:NAME[+NAME]")
    from training.controller.model_controller import controller_from

    with pytest.raises(ValueError, match="at most one start phase"):
        controller_from("model:teacher_robust+start_rest+start_rest")


def test_a_device_lock_is_refused_before_it_is_opened(run):
    if os.geteuid() != 0:
        pytest.skip("making a device node needs root")
    os.mknod(run / ".lock", 0o600 | __import__("stat").S_IFCHR, os.makedev(1, 3))
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, ".lock", "a device")


def test_a_run_with_no_snapshot_to_continue_is_not_restarted_from_zero(run):
    """A run without a teacher continues from a PPO checkpoint only, never from imitation/."""
    shutil.rmtree(run / "checkpoints")
    shutil.copytree(run / "best", run / "imitation")
    rows = (run / "eval.csv").read_text()
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, "no complete snapshot to continue from")
    assert (run / "eval.csv").read_text() == rows


def test_a_linear_schedule_run_can_be_extended(tmp_path):
    args = SMALL + ["--out-dir", str(tmp_path), "--total-timesteps", "512", "--lr-schedule"]
    args += ["linear", "--checkpoint-freq", "256", "--eval-freq", "256"]
    assert train_ppo.main(args) == 0
    (run,) = (tmp_path / "train_ppo").iterdir()
    assert train_ppo.main(["--resume", str(run), "--total-timesteps", "1024"]) == 0
    assert load_state(run / "final")["num_timesteps"] >= 1024


def test_a_checkpoint_folder_linked_outside_is_refused_before_it_is_read(tmp_path, victim):
    run = _policy_copy(tmp_path)
    (victim.parent / "latest").mkdir()
    (run / "checkpoints").symlink_to(victim.parent)
    _evaluate_refused(run, tmp_path, "symlink", extra=["--which", "checkpoint"])


def test_a_teacher_runs_observation_statistics_are_refused(tmp_path):
    run = _policy_copy(tmp_path, "ppo_walker")
    path = run / "final" / NORMALIZER_FILE
    with np.load(path) as z:
        d = {k: z[k] for k in z.files}
    n = 26  # the config's observation (with the clock)
    d.update(norm_obs=np.float64(1.0), obs_mean=np.zeros(n), obs_var=np.ones(n))
    np.savez(path, **d)
    write_manifest(path.parent)
    _evaluate_refused(run, tmp_path, "normalises its own input")


def test_a_stopped_flag_that_is_not_a_boolean_is_refused(run):
    _state(run, stopped="yes")
    with pytest.raises(SystemExit) as e:
        train_ppo.main(["--resume", str(run), "--progress", "false"])
    _one_line_refusal(e, "stopped must be a boolean")


def test_a_runs_command_txt_pastes_back_as_it_ran(tmp_path):
    """command.txt is the command line shell-quoted: a TOML table flag splits back whole."""
    import shlex

    from training.plumbing.common import make_run_dir
    from training.ppo.config import PPOConfig

    argv = ["--seed", "3", "--train-env", "start={stride=0.2, rest=0.8}", "--out-dir", "a b"]
    run = make_run_dir(tmp_path, "train_ppo", "ConstrainedBiped-v0", 3, PPOConfig(), argv)
    run.close()
    (path,) = (tmp_path / "train_ppo").iterdir()
    words = shlex.split((path / "command.txt").read_text())
    assert words[1:3] == ["-m", "training.train_ppo"] and words[3:] == argv


def test_a_recorded_empty_folder_is_not_deleted_with_what_a_run_put_in_it(tmp_path):
    """Finding: an output record listing an empty folder of this command made its next run
    delete that folder after moving its new files in (theirs and another command's)."""
    out = tmp_path / "out"
    with command_output(out, "cmd_a") as co:
        co.dir("figures")  # an empty folder: recorded as "figures/"
        co.dir().write("a.json", "1")
    assert json.loads((out / MARKER).read_text())["files"]["figures/"] == "cmd_a"
    with command_output(out, "cmd_b") as co:
        co.dir("figures").write("b.png", "theirs")
    with command_output(out, "cmd_a") as co:
        co.dir("figures").write("a.png", "new")
    assert (out / "figures" / "a.png").read_text() == "new"
    assert (out / "figures" / "b.png").read_text() == "theirs"
    with command_output(out, "cmd_c") as co:  # a command's empty folder, then not written again
        co.dir("empty")
    with command_output(out, "cmd_c") as co:
        co.dir().write("c.txt", "3")
    assert not (out / "empty").exists() and (out / "c.txt").read_text() == "3"


def test_a_crafted_record_cannot_claim_a_users_file_nor_a_changed_one(tmp_path):
    """Finding: a crafted .written_by.json claimed a user's file for a command (which then
    replaced or deleted it); the record now holds each file's SHA-256, and a file whose content
    is not what the command wrote is foreign."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "thesis.txt").write_text("precious")
    (out / MARKER).write_text(json.dumps({"files": {"thesis.txt": "cmd_a"}}))
    with pytest.raises(UntrustedFileError, match="thesis.txt"), command_output(out, "cmd_a"):
        pass
    (out / MARKER).write_text(json.dumps({"files": {"thesis.txt": "cmd_a"},
                                          "sha256": {"thesis.txt": "0" * 64}}))  # fmt: skip
    with pytest.raises(UntrustedFileError, match="thesis.txt"), command_output(out, "cmd_a"):
        pass
    assert (out / "thesis.txt").read_text() == "precious"
    other = tmp_path / "other"
    with command_output(other, "cmd_a") as co:
        co.dir().write("a.json", "1")
    with command_output(other, "cmd_a") as co:  # as it wrote it: its own, replaced
        co.dir().write("a.json", "2")
    (other / "a.json").write_text("edited by hand")
    with pytest.raises(UntrustedFileError, match="changed since"), command_output(other, "cmd_a"):
        pass
    assert (other / "a.json").read_text() == "edited by hand"


def test_a_whole_directory_command_holds_only_the_names_it_writes(tmp_path):
    """Finding: a record {"*": command} skipped the foreign-file check for that command."""
    out = tmp_path / "sweep"
    with command_output(out, "sweep", whole=("tune", "results.csv")):
        (out / "tune").mkdir()
        (out / "results.csv").write_text("seed\n0\n")
    with command_output(out, "sweep", whole=("tune", "results.csv")):  # its own: again
        pass
    crafted = tmp_path / "crafted"
    crafted.mkdir()
    (crafted / "notes.txt").write_text("mine")
    (crafted / MARKER).write_text(json.dumps({"files": {"*": "sweep"}}))
    with (
        pytest.raises(UntrustedFileError, match="notes.txt"),
        command_output(crafted, "sweep", whole=("tune", "results.csv")),
    ):
        pass
    with (
        pytest.raises(UntrustedFileError, match="the output of sweep"),
        command_output(out, "evaluate"),
    ):
        pass


def test_a_command_that_fails_leaves_no_output_folder_it_made(tmp_path):
    """Finding: an interrupted evaluation said its --out was as it was, yet left it created
    and empty."""
    out = tmp_path / "new" / "out"
    for exc in (KeyboardInterrupt, RuntimeError):
        with pytest.raises(exc), command_output(out, "evaluate") as co:
            co.dir().write("half.json", "{}")
            raise exc
        assert not out.exists()
    out.mkdir(parents=True)  # one the user made: stays
    with pytest.raises(RuntimeError), command_output(out, "evaluate"):
        raise RuntimeError
    assert out.is_dir()


def test_evaluate_refuses_a_wrong_path_or_out_before_loading_anything(tmp_path, capsys):
    """Findings: a wrong policy path first printed a snapshot line and loaded for seconds; a
    refused --out came after the policy and the simulator were loaded."""
    with pytest.raises(SystemExit):
        evaluate.main([str(tmp_path / "nope")])
    out, err = capsys.readouterr()
    assert "no such directory" in err and "snapshot" not in out and "loading" not in out
    with pytest.raises(SystemExit):
        evaluate.main([str(ROOT / "policies" / "ppo_gait_50hz"), "--out", str(ROOT / "policies")])
    out, err = capsys.readouterr()
    assert "--out" in err and "loading" not in out
    (tmp_path / "afile").write_text("x")
    with pytest.raises(SystemExit):
        evaluate.main([str(ROOT / "policies" / "ppo_gait_50hz"), "--out",
                       str(tmp_path / "afile" / "sub")])  # fmt: skip
    out, err = capsys.readouterr()
    assert "not a directory" in err and "loading" not in out


# ------------------------------------------------------------------ disks, and a snapshot replaced
@pytest.fixture
def small_tmpfs(tmp_path):
    """A 256 kB tmpfs this test mounts (root only; skipped where mounting is not allowed)."""
    where = tmp_path / "disk"
    where.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(where)],
                       capture_output=True, text=True)  # fmt: skip
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


@pytest.mark.parametrize("disk", ["full", "read-only"])
def test_a_full_or_read_only_disk_is_a_one_line_refusal_that_leaves_nothing(small_tmpfs, disk,
                                                                             capsys):  # fmt: skip
    out = small_tmpfs / "eval"
    if disk == "full":
        (small_tmpfs / "filler").write_bytes(b"\0" * (256 * 1024 - 8192))  # nearly full
    else:
        subprocess.run(["mount", "-o", "remount,ro", str(small_tmpfs)], check=True)
    before = sorted(p.name for p in small_tmpfs.iterdir())
    with pytest.raises(SystemExit) as e:
        evaluate.main([str(ROOT / "policies" / "ppo_gait_50hz"), "--episodes", "1", "--out",
                       str(out)])  # fmt: skip
    msg = str(e.value)
    want = "the disk is full" if disk == "full" else "read-only file system"
    out_text, err = capsys.readouterr()
    assert want in msg and "\n" not in msg and "Traceback" not in err, msg
    assert sorted(p.name for p in small_tmpfs.iterdir()) == before  # nothing left behind
    if disk == "read-only":  # known before anything is loaded
        assert "loading" not in out_text


def test_a_snapshot_loads_whole_while_another_process_replaces_it(tmp_path):
    """A run publishing its snapshot (atomic_dir: the new one renamed in, the old kept as
    NAME.prev) while a reader loads it: every load gets one complete snapshot."""
    import multiprocessing as mp

    from training.ppo.policy_io import POLICY_FILE, open_snapshot

    run = tmp_path / "run"
    shutil.copytree(ROOT / "policies" / "ppo_gait_50hz", run,
                    ignore=shutil.ignore_patterns("figures", "best", "published.json"))  # fmt: skip
    files = {p.name: p.read_bytes() for p in (run / "final").iterdir() if p.name != "manifest.json"}
    ctx = mp.get_context("fork")
    stop, count = ctx.Event(), ctx.Value("i", 0)
    writer = ctx.Process(target=_replace_snapshots, args=(run / "final", files, stop, count))
    writer.start()
    loads, t0 = 0, time.time()
    try:
        while (count.value < 200 or loads < 200) and time.time() - t0 < 120:  # both, any speeds
            snap = open_snapshot(run, "final")
            assert snap.files[POLICY_FILE] == files[POLICY_FILE]
            loads += 1
    finally:
        stop.set()
        writer.join()
    assert count.value >= 200 and loads >= 200  # many loads during many replacements


def _replace_snapshots(where, files, stop, count):
    from training.ppo.policy_io import atomic_dir

    while not stop.is_set():
        with atomic_dir(where) as tmp:
            for name, data in files.items():
                (tmp / name).write_bytes(data)
        count.value += 1
