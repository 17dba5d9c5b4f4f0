"""Starting the package's commands as child processes in tests."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

COMMANDS = [  # every command of the package, as `python -m` runs it
    "training.ppo.train", "training.evaluation.evaluate", "training.evaluation.compare",
    "training.paper.open_loop", "training.paper.optimize_open_loop",
    "training.paper.paper_numerics", "training.paper.table2_study",
    "training.controller.record_reference", "training.controller.tune",
    "training.controller.model_controller", "training.ppo.policy_io", "training.ppo.sweep",
    "benchmarks.accuracy", "benchmarks.bench_ab", "benchmarks.bench_bounds",
    "benchmarks.bench_core",
    "benchmarks.bench_env", "benchmarks.bench_ppo", "benchmarks.failure_modes",
]  # fmt: skip


def default_sigint() -> None:
    """``preexec_fn``: Ctrl-C's default in the child, however pytest was started.

    A shell starts a background job with SIGINT ignored, and a child inherits that: Python
    then installs no KeyboardInterrupt handler, and a test that interrupts a command would
    find it running on.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(module: str, args: list[str], cwd: Path = ROOT) -> subprocess.Popen:
    """``python -m module args`` as a child on one numba thread, its stderr piped to read.

    Its stdout is dropped and Ctrl-C has its default there (:func:`default_sigint`), so a test
    can interrupt it and read what it said.
    """
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", module, *args], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=default_sigint)  # fmt: skip
