"""A policy directory is untrusted input (docs/policy_files.md, Threat model).

Each crafted directory is refused with one line naming the file and what was expected (a
``SystemExit`` whose message is that line), with no effect outside the directory: no marker
file, no output directory. The attacker controls every byte, manifests included, so most
cases rewrite the manifest after tampering: the checks behind it must hold on their own.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from subprocs import COMMANDS, start

from training.evaluation import evaluate
from training.plumbing.outputs import MARKER, OutDir, RunLock
from training.ppo import train as train_ppo
from training.ppo.policy_io import write_manifest

ROOT = Path(__file__).resolve().parents[1]
SCRATCH = ROOT / "policies" / "ppo_gait_50hz"  # a committed policy


@pytest.fixture
def policy(tmp_path, monkeypatch):
    """A copy of a committed policy (its final/ snapshot, no figures), the cwd a scratch folder."""
    run = tmp_path / "policies" / "evil"
    shutil.copytree(
        SCRATCH, run, ignore=shutil.ignore_patterns("figures", "best", "published.json")
    )
    monkeypatch.chdir(tmp_path)
    return run


def _config(run: Path, **changes) -> None:
    lines = (run / "config.toml").read_text().splitlines()
    for key, value in changes.items():  # top-level keys, before the [env] tables
        lines = [ln for ln in lines if not ln.startswith(f"{key} =")]
        lines.insert(0, f"{key} = {value}")
    (run / "config.toml").write_text("\n".join(lines) + "\n")


def _refused(run: Path, match: str, tmp: Path, extra=()) -> None:
    out = tmp / "out"
    with pytest.raises(SystemExit) as e:
        evaluate.main([str(run), "--episodes", "1", "--out", str(out), *extra])
    msg = str(e.value)
    assert match in msg, msg
    assert "\n" not in msg and "Traceback" not in msg  # one line
    assert not out.exists() and not (tmp / "PWNED").exists() and not Path("PWNED").exists()


def _norm(run: Path) -> dict:
    with np.load(run / "final" / "normalizer.npz") as z:
        return {k: z[k] for k in z.files}


def _rewrite_norm(run: Path, **changes) -> None:
    d = {**_norm(run), **changes}
    d = {k: v for k, v in d.items() if v is not None}
    np.savez(run / "final" / "normalizer.npz", **d)
    write_manifest(run / "final")


# ---------------------------------------------------------------- the reproducers
def test_env_id_cannot_import_a_module(policy, tmp_path):
    (policy / "payload.py").write_text('open("PWNED", "w").write("ran")\n')
    _config(policy, env_id='"policies.evil.payload:ConstrainedBiped-v0"')
    _refused(policy, "env-id must be one of ['ConstrainedBiped-v0']", tmp_path)


def test_env_id_module_is_not_imported_by_a_subprocess_either(policy, tmp_path):
    """As the issue ran it: ``python -m`` from the directory holding the payload."""
    (policy / "payload.py").write_text('open("PWNED", "w").write("ran")\n')
    _config(policy, env_id='"policies.evil.payload:ConstrainedBiped-v0"')
    cmd = [sys.executable, "-m", "training.evaluation.evaluate", "policies/evil", "--episodes", "1"]
    p = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert p.returncode != 0 and "env-id" in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "PWNED").exists() and not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("base_controller", '"model:/etc/passwd"'),
        ("teacher", '"model:../../../etc/passwd"'),
        ("teacher", '"model:teacher_robust+/tmp/x.json"'),
        ("reference", '"/tmp/reference.npz"'),
        ("resume", '"/tmp/elsewhere"'),
    ],
)
def test_no_path_in_a_config_is_read(policy, tmp_path, key, value):
    _config(policy, **{key: value})
    _refused(policy, key.replace("_", "-") if key == "reference" else key, tmp_path)


@pytest.mark.parametrize(
    ("arch", "match"),
    [
        ("[12000, 12000]", "--net-arch must be in [1, 4096]"),  # out of range
        ("[4000, 4000, 4000]", "the config says net_arch [4000, 4000, 4000]"),  # not the weights'
    ],
)
def test_a_huge_network_is_refused_before_it_is_built(policy, tmp_path, arch, match):
    _config(policy, net_arch=arch)
    _refused(policy, match, tmp_path)


def test_a_decompression_bomb_normaliser_is_refused_from_its_header(policy, tmp_path):
    path = policy / "final" / "normalizer.npz"
    d = _norm(policy)
    d["obs_mean"] = np.zeros(20_000_000)  # 160 MB of zeros: a few hundred kB compressed
    np.savez_compressed(path, **d)
    write_manifest(policy / "final")
    assert path.stat().st_size < 1_000_000
    _refused(policy, "obs_mean declares 160000128 bytes, more than", tmp_path)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda n: {"obs_mean": None}, "expected exactly"),  # a member missing
        (lambda n: {"obs_mean": np.float64(0.0)}, "obs_mean is float64 ()"),  # a scalar
        (lambda n: {"obs_var": np.ones(3)}, "observation statistics of length"),
        (lambda n: {"obs_mean": np.zeros((n, 1))}, "obs_mean is float64"),  # wrong shape
        (lambda n: {"obs_mean": np.zeros(n, np.int64)}, "expected kind 'f'"),  # wrong dtype
        (lambda n: {"obs_var": np.full(n, np.nan)}, "NaN or inf"),
        (lambda n: {"obs_var": -np.ones(n)}, "obs_var is negative"),
        (lambda n: {"extra": np.zeros(2)}, "expected exactly"),
        (lambda n: {"norm_obs": np.float64(0.0)}, "holds no observation statistics"),
    ],
)
def test_bad_normalisers_are_refused(policy, tmp_path, change, match):
    n = len(_norm(policy)["obs_mean"])
    _rewrite_norm(policy, **change(n))
    _refused(policy, match, tmp_path)


def test_a_missing_normaliser_is_refused(policy, tmp_path):
    (policy / "final" / "normalizer.npz").unlink()
    write_manifest(policy / "final")
    _refused(policy, "normalizer.npz: missing", tmp_path)


def test_an_object_array_is_never_unpickled(policy, tmp_path):
    path = policy / "final" / "normalizer.npz"
    d = _norm(policy)
    d["obs_mean"] = np.array([{"a": 1}], dtype=object)
    np.savez(path, **d, allow_pickle=True)
    write_manifest(policy / "final")
    _refused(policy, "dtype '|O' (plain little-endian numbers only)", tmp_path)


def _weights(run: Path) -> Path:
    return run / "final" / "policy.safetensors"


def _set_tensor(run: Path, name: str, fn) -> None:
    from safetensors.numpy import load_file, save_file

    t = load_file(str(_weights(run)))
    t[name] = fn(t[name])
    save_file(t, str(_weights(run)))
    write_manifest(run / "final")


def test_nan_weights_are_refused(policy, tmp_path):
    _set_tensor(policy, "action_net.bias", lambda a: np.full_like(a, np.nan))
    _refused(policy, "holds NaN or inf", tmp_path)


def test_weights_of_another_shape_are_refused(policy, tmp_path):
    _set_tensor(policy, "action_net.weight", lambda a: np.zeros((4, a.shape[1]), a.dtype))
    _refused(policy, "action_net", tmp_path)


@pytest.mark.parametrize(
    ("damage", "match"),
    [
        (lambda p: p.write_bytes(p.read_bytes()[:1000]), "bytes in a 1000-byte file"),
        (lambda p: p.write_bytes(p.read_bytes()[:-4]), "the header describes"),  # truncated
        (lambda p: p.write_bytes(b""), "truncated"),  # empty
        (lambda p: p.write_bytes(struct.pack("<Q", 1 << 40) + b"{}"), "header of"),  # huge header
        (lambda p: p.write_bytes(struct.pack("<Q", 2) + b"[]"), "not a JSON object"),
        (lambda p: p.write_bytes(b"\x93NUMPY" + b"\0" * 100), "header of"),  # not safetensors
    ],
)
def test_damaged_weights_are_refused(policy, tmp_path, damage, match):
    damage(_weights(policy))
    write_manifest(policy / "final")
    _refused(policy, match, tmp_path)


@pytest.mark.parametrize(
    ("state", "match"),
    [
        ('{"num_timesteps": -5}', "num_timesteps must be an integer in [0, "),
        ('{"num_timesteps": "many"}', "num_timesteps must be an integer in [0, "),
        ("[1, 2]", "a JSON object expected"),
        ("[" * 100_000 + "]" * 100_000, "not valid JSON"),  # nested beyond recursion
        ("{not json", "not valid JSON"),
    ],
)
def test_bad_state_files_are_refused(policy, tmp_path, state, match):
    (policy / "final" / "state.json").write_text(state)
    write_manifest(policy / "final")
    _refused(policy, match, tmp_path)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("n_envs = 'abc'\n", "n_envs must be an integer"),
        ("n_envs = 0\n", "n-envs must be in"),
        ("net_arch = [[1, 2]]\n", "net_arch must be a list"),
        ("surprise = 1\n", "unknown keys ['surprise']"),
        ("gamma = inf\n", "gamma must be finite"),
        ("x = [\n", "not valid TOML"),
        ("# " + "a" * (2 << 20) + "\n", "bytes, more than 1048576 allowed"),
        ('[env]\nreference = "/tmp/x.npz"\n', "reference must be a shipped name"),
        ("[env]\nimport_me = 1\n", "unknown argument(s) of ConstrainedBiped-v0: 'import_me'"),
        ("[env]\ndt = -1\n", "[env]: dt must be"),
        (
            "[train_env]\nperturbations = {push_impulse_ns = 1e9, push_at_s = 1}\n",
            "push_impulse_ns",
        ),
        ("env = 3\n", "env must be a table"),
    ],
)
def test_bad_configs_are_refused(policy, tmp_path, text, match):
    body = (policy / "config.toml").read_text()
    if text.startswith(("[", "env =")):  # a table (or a key in its place) replaces them
        body = body.split("\n[", 1)[0] + "\n" + (text if text.startswith("[") else "")
    elif not text.startswith(("surprise", "# ", "x = [")):
        key = text.split(" =")[0]
        body = "".join(ln + "\n" for ln in body.splitlines() if not ln.startswith(key))
    if not text.startswith("["):
        body = text + body  # top-level keys go before the tables
    (policy / "config.toml").write_text(body)
    _refused(policy, match, tmp_path)


def test_symlinks_are_not_followed(policy, tmp_path):
    (policy / "config.toml").rename(tmp_path / "real.toml")
    (policy / "config.toml").symlink_to(tmp_path / "real.toml")
    _refused(policy, "a symlink", tmp_path)


def test_a_symlinked_snapshot_file_is_not_read(policy, tmp_path):
    norm = policy / "final" / "normalizer.npz"
    norm.rename(tmp_path / "n.npz")
    norm.symlink_to(tmp_path / "n.npz")
    _refused(policy, "no complete 'final' snapshot", tmp_path)


def test_a_damaged_newest_snapshot_falls_back_to_the_previous(policy, tmp_path, capsys):
    shutil.copytree(policy / "final", policy / "final.prev")
    w = _weights(policy)
    w.write_bytes(w.read_bytes()[:1000])  # truncated, its manifest now wrong
    from training.ppo.policy_io import find_snapshot, load_policy

    assert find_snapshot(policy, "final") == policy / "final.prev"
    assert "damaged" in capsys.readouterr().err
    load_policy(policy, "final")


def test_no_snapshot_no_config_not_a_directory(policy, tmp_path):
    shutil.rmtree(policy / "final")
    _refused(policy, "no complete 'final' snapshot", tmp_path)
    (policy / "config.toml").unlink()
    _refused(policy, "not a run directory", tmp_path)
    _refused(tmp_path / "nowhere", "no such directory", tmp_path)


def test_evaluate_never_writes_into_a_run_directory_or_through_a_link(policy, tmp_path):
    with pytest.raises(SystemExit, match="which no command of this package wrote there"):
        evaluate.main([str(policy), "--out", str(policy)])
    (tmp_path / "target").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "target")
    with pytest.raises(SystemExit, match="a symlink"):
        evaluate.main([str(policy), "--episodes", "1", "--out", str(tmp_path / "link")])
    assert not any((tmp_path / "target").iterdir())


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--dt", "-1"], "--dt: must be in"),
        (["--episodes", "0"], "--episodes: must be in"),
        (["--episodes", "abc"], "--episodes: invalid integer value"),
        (["--seed", "-3"], "--seed: must be in"),
        (["--which", "nope"], "--which: invalid choice"),
    ],
)
def test_evaluate_flags_are_checked(policy, tmp_path, args, match):
    _refused(policy, match, tmp_path, args)


# ---------------------------------------------------------------- training CLI and runs
@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--total-timesteps", "abc"], "--total-timesteps: invalid int value"),
        (["--n-envs", "0"], "--n-envs must be in"),
        (["--total-timesteps", "-5"], "--total-timesteps must be in"),
        (["--resume", "/nonexistent/run"], "--resume: /nonexistent/run: no such directory"),
        (["--out-dir", "/proc/no/such"], "--out-dir /proc/no/such: cannot create the run"),
        (["--env-id", "os:Anything"], "--env-id must be one of"),
        (["--config", "/nonexistent.toml"], "--config: /nonexistent.toml: missing"),
    ],
)
def test_train_flags_are_refused_before_a_run_directory_exists(tmp_path, args, match):
    out = ["--out-dir", str(tmp_path / "runs")] if "--out-dir" not in args else []
    with pytest.raises(SystemExit) as e:
        train_ppo.main([*out, *args])
    assert match in str(e.value) and "\n" not in str(e.value)
    assert not (tmp_path / "runs").exists()


def test_resume_of_a_run_without_a_snapshot_is_refused_by_name(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(SCRATCH / "config.toml", run / "config.toml")
    with pytest.raises(SystemExit, match="no complete snapshot to continue from"):
        train_ppo.main(["--resume", str(run)])
    assert sorted(p.name for p in run.iterdir()) == [".lock", "config.toml"]  # nothing restarted


def test_a_second_writer_is_refused_naming_the_holder(tmp_path):
    run = tmp_path / "run"
    shutil.copytree(SCRATCH, run, ignore=shutil.ignore_patterns("figures"))
    shutil.copytree(run / "final", run / "checkpoints" / "latest")
    with OutDir.open(run) as d, RunLock(d):
        with pytest.raises(SystemExit, match=f"in use by pid {os.getpid()}"):
            train_ppo.main(["--resume", str(run)])
    with OutDir.open(run) as d, RunLock(d):  # released by the holder: the next writer gets it
        pass


# ---------------------------------------------------------------- interrupted evaluations
def _evaluate_proc(out: Path, cwd: Path) -> subprocess.Popen:
    args = [str(SCRATCH), "--episodes", "3", "--out", str(out)]
    return start("training.evaluation.evaluate", args, cwd=cwd)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL])
def test_an_interrupted_evaluation_leaves_the_old_output(tmp_path, sig):
    out = tmp_path / "eval"
    out.mkdir()
    (out / "evaluation.json").write_text('{"old": true}\n')
    digest = hashlib.sha256((out / "evaluation.json").read_bytes()).hexdigest()
    (out / MARKER).write_text(json.dumps({"files": {"evaluation.json": "evaluate"},
                                          "sha256": {"evaluation.json": digest}}))  # fmt: skip
    proc = _evaluate_proc(out, tmp_path)
    t0 = time.time()
    while not list(out.glob(".staging-*/figures")):
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        assert time.time() - t0 < 300
        time.sleep(0.02)
    proc.send_signal(sig)
    proc.wait(timeout=60)
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert proc.returncode != 0
    if sig == signal.SIGINT:  # one line naming what is kept, no traceback
        assert "Traceback" not in err and "interrupted; nothing was written" in err, err
    assert json.loads((out / "evaluation.json").read_text()) == {"old": True}
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".staging-")) == [
        MARKER,
        "evaluation.json",
    ]
    if sig == signal.SIGINT:  # an interrupt cleans its temporary folder up
        assert not list(out.glob(".staging-*"))


# ---------------------------------------------------------------- every command's --help


def test_every_command_answers_help_without_side_effects(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = {
        m: subprocess.Popen(
            [sys.executable, "-m", m, "--help"],
            cwd=tmp_path,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        for m in COMMANDS
    }
    for m, p in procs.items():
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, f"{m}: {err[-1500:]}"
        assert "usage" in out.lower(), m
    assert list(tmp_path.iterdir()) == []  # nothing written
    committed = subprocess.run(
        ["git", "status", "--porcelain", "--", "benchmarks/results", "policies"],
        cwd=ROOT, capture_output=True, text=True,
    ).stdout  # fmt: skip
    assert committed == ""


def test_the_zip_reader_refuses_a_stored_size_beyond_the_header(tmp_path):
    """An npz member whose stored bytes exceed what its header's shape needs."""
    from training.plumbing.safe_files import UntrustedFileError, read_npz

    path = tmp_path / "x.npz"
    np.savez(path, a=np.zeros(4))
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.zeros(1))
    with zipfile.ZipFile(path, "a") as zf:
        zf.writestr("b.npy", buf.getvalue() + b"\0" * 100_000)
    with pytest.raises(UntrustedFileError, match="stores"):
        read_npz(path, {"a": ((4,), "f"), "b": ((1,), "f")})


def test_an_imported_sb3_model_is_a_run_directory_that_evaluates(tmp_path, capsys):
    """``policy_io import-sb3`` (pickles the user trusts) writes config.toml + final/."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from training.ppo.policy_io import main as policy_io_main
    from training.ppo.sb3_vec import make_sb3_vec_env

    venv = VecNormalize(make_sb3_vec_env(2, 0, {"task": "track", "dt": 0.02}, "batched"))
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=32, n_epochs=1, device="cpu")
    model.learn(64)
    model.save(tmp_path / "model.zip")
    venv.save(str(tmp_path / "vecnormalize.pkl"))
    out = tmp_path / "imported"
    argv = ["import-sb3", str(tmp_path / "model.zip"), "--out", str(out)]
    argv += ["--vecnormalize", str(tmp_path / "vecnormalize.pkl")]
    with pytest.raises(SystemExit, match="observes 26 entries"):  # the env it trained in
        policy_io_main(argv)
    assert policy_io_main([*argv, "--env", 'task="track"', "dt=0.02"]) == 0
    assert "unpickles" in capsys.readouterr().err  # the warning
    assert (out / "config.toml").is_file() and (out / "final" / "manifest.json").is_file()
    from training.ppo.policy_io import read_config

    assert read_config(out).env == {"task": "track", "dt": 0.02}
    assert evaluate.main([str(out), "--episodes", "1", "--out", str(tmp_path / "ev")]) == 0
    assert (tmp_path / "ev" / "evaluation.json").is_file()


def test_resume_of_a_crafted_run_imports_nothing(policy, tmp_path):
    (policy / "payload.py").write_text('open("PWNED", "w").write("ran")\n')
    _config(policy, env_id='"policies.evil.payload:ConstrainedBiped-v0"')
    with pytest.raises(SystemExit, match="env-id must be one of"):
        train_ppo.main(["--resume", str(policy)])
    assert not (tmp_path / "PWNED").exists()
