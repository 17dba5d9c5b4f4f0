"""Independent jobs on Ray (optional extra ``[distributed]``), or serially, in the same order.

The studies and searches (``table2_study``, ``optimize_open_loop``, ``controller.tune``)
hand their independent batches to :func:`run_tasks`: without Ray they run one after another in
this process (or, for the controller tuning, in a local process pool); with ``--ray`` each batch
is a Ray task on one CPU with one numba thread, on a local Ray instance, or on a cluster with
``--ray-address HOST:PORT`` (``ray start --head`` prints it). The results come back in the order
of the jobs, so a run on Ray gives exactly the serial run's result. Nothing here is needed by the
environment or by the default install.
"""

from __future__ import annotations

import os
import socket
import sys
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from training.plumbing.common import progress

WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""Environment of every Ray worker: one thread per task (the task is the unit of parallelism)."""
CONNECT_TIMEOUT_S = 5.0
"""How long an address may take to accept a TCP connection before it counts as unreachable."""


class TasksFailed(RuntimeError):
    """Some tasks raised.

    ``results`` holds every other task's result (None where one failed) and ``failures``
    (index, description of the arguments, error text) the failed ones, in task order
    (Ray finishes tasks in any order).
    """

    def __init__(self, failures: list[tuple[int, str, str]], results: list[Any]):
        """Store the failures and the kept results; the message lists each failure."""
        failures = sorted(failures, key=lambda f: f[0])
        lines = [f"task {i} ({args}) failed: {err}" for i, args, err in failures]
        super().__init__(f"{len(failures)} of {len(results)} tasks failed:\n" + "\n".join(lines))
        self.failures = failures
        self.results = results


def describe(args: Sequence[Any]) -> str:
    """Short text of a job's arguments (arrays by shape and dtype)."""

    def one(a: Any) -> str:
        if isinstance(a, np.ndarray):
            return f"array{a.shape} {a.dtype}"
        text = repr(a)
        return text if len(text) <= 80 else text[:77] + "..."

    return ", ".join(one(a) for a in args)


def _import_ray():
    try:
        import ray
    except ImportError:
        raise ImportError(
            "Ray is not installed: pip install -e '.[distributed]' (or run without --ray)"
        ) from None
    return ray


def check_address(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Raise ConnectionError naming ``address`` unless HOST:PORT accepts a TCP connection.

    Ray's own connection attempt retries for about a minute; this answers within seconds.
    ``"auto"`` and ``ray://`` client addresses are passed to Ray unchecked.
    """
    if address == "auto":
        return
    hostport = address.removeprefix("ray://")
    host, sep, port = hostport.rpartition(":")
    if not sep or not port.isdigit():
        raise ValueError(f"a Ray address is HOST:PORT (or 'auto'), got {address!r}")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as e:
        raise ConnectionError(
            f"no Ray cluster reachable at {address!r} ({e}); start one with `ray start --head` "
            "and pass the address it prints, or use --ray for a local instance"
        ) from None


def init_ray(address: str | None = None, num_cpus: int | None = None, threads: int = 1):
    """Connect to the Ray cluster at ``address``, or start a local instance (None or "").

    The workers get :data:`WORKER_ENV` (one thread each), with numba allowed ``threads``
    threads (a sweep's trial holding several CPUs: ``train_ppo --env-threads`` up to that).
    Returns the ``ray`` module.
    """
    ray = _import_ray()
    if ray.is_initialized():
        return ray
    runtime_env = {"env_vars": {**WORKER_ENV, "NUMBA_NUM_THREADS": str(threads)}}
    if address:
        check_address(address)
        ray.init(address=address, runtime_env=runtime_env, log_to_driver=False)
    else:
        ray.init(num_cpus=num_cpus, runtime_env=runtime_env, log_to_driver=False)
    return ray


def connect(
    use_ray: bool, address: str = "", num_cpus: int | None = None, threads: int = 1
) -> None:
    """For a command line: start or join Ray up front when asked, before any work is done.

    ``threads``: numba threads a worker may use (:func:`init_ray`). An unreachable address
    or a missing Ray ends the program with a one-line message.
    """
    if not (use_ray or address):
        return
    try:
        init_ray(address or None, num_cpus=num_cpus, threads=threads)
    except (ConnectionError, ImportError, ValueError) as e:
        raise SystemExit(f"error: {e}") from None


def run_tasks(
    fn: Callable[..., Any],
    jobs: Sequence[tuple],
    *,
    use_ray: bool = False,
    ray_address: str = "",
    workers: int = 1,
    desc: str = "",
    show: bool = False,
) -> list[Any]:
    """``[fn(*job) for job in jobs]``: serially, in a local process pool, or as Ray tasks.

    Args:
        fn: a module-level function (Ray and the process pool import it by name).
        jobs: argument tuples, one per task.
        use_ray: run each job as a Ray task (one CPU, one numba thread); ``ray_address``
            (HOST:PORT) joins a running cluster, else a local instance is started.
        workers: without Ray, the number of local processes (1: in this process).
        desc, show: a progress bar over the tasks as they finish.

    Returns:
        The results in the order of ``jobs``, whichever finished first.

    Raises:
        TasksFailed: after every task has finished, when some raised; it names each failed
            task with its arguments and keeps the other results.
    """
    jobs = list(jobs)
    if use_ray or ray_address:
        return _run_ray(fn, jobs, ray_address, desc, show)
    results: list[Any] = [None] * len(jobs)
    failures = []
    if workers > 1:
        from multiprocessing import Pool

        with Pool(workers) as pool:
            handles = [pool.apply_async(fn, job) for job in jobs]
            for i in progress(range(len(jobs)), len(jobs), desc, show):
                try:
                    results[i] = handles[i].get()
                except Exception as e:  # noqa: BLE001 (reported with its arguments below)
                    failures.append((i, describe(jobs[i]), f"{type(e).__name__}: {e}"))
    else:
        for i in progress(range(len(jobs)), len(jobs), desc, show):
            try:
                results[i] = fn(*jobs[i])
            except Exception as e:  # noqa: BLE001
                failures.append((i, describe(jobs[i]), f"{type(e).__name__}: {e}"))
    if failures:
        raise TasksFailed(failures, results)
    return results


def _run_ray(fn, jobs, address, desc, show):
    ray = init_ray(address or None)
    remote = ray.remote(num_cpus=1, max_retries=0)(fn)
    refs = [remote.remote(*job) for job in jobs]
    index = {ref: i for i, ref in enumerate(refs)}
    results: list[Any] = [None] * len(jobs)
    failures = []
    pending = list(refs)
    bar = progress(range(len(jobs)), len(jobs), desc, show)  # advanced by hand below
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        i = index[done[0]]
        try:
            results[i] = ray.get(done[0])
        except Exception as e:  # noqa: BLE001 (a task's error, reported with its arguments)
            cause = getattr(e, "cause", None) or e
            failures.append((i, describe(jobs[i]), f"{type(cause).__name__}: {cause}"))
            print(f"task {i} ({describe(jobs[i])}) failed: {cause}", file=sys.stderr)
        if hasattr(bar, "update"):  # a tqdm bar (progress() returns the range without one)
            bar.update(1)
    if hasattr(bar, "close"):
        bar.close()
    if failures:
        raise TasksFailed(failures, results)
    return results


def shutdown() -> None:
    """Shut down the Ray instance this process started or joined (no-op without one)."""
    if "ray" in sys.modules:
        import ray

        if ray.is_initialized():
            ray.shutdown()


def cpu_count() -> int:
    """CPUs of the Ray cluster this process is connected to (else of this machine)."""
    if "ray" in sys.modules:
        import ray

        if ray.is_initialized():
            return int(ray.cluster_resources().get("CPU", 1))
    return os.cpu_count() or 1
