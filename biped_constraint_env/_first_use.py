"""The compiled cache: cleared when any source changed, and word of a compile while it runs.

numba checks a cached function against its own source file only, not against the files of
the functions it calls and compiles in; after an edit to one module (a developer's checkout, a
``git pull`` of an editable install) the cached code of the others would still run the old
version. So the package keeps a stamp of all its sources (names, sizes, modification times)
beside the cache and drops every cached function when it differs.
"""

from __future__ import annotations

import hashlib
import os
import sys
import threading
import time
from pathlib import Path

from numba.core import event as _event

_PACKAGE = Path(__file__).resolve().parent
_CACHE = _PACKAGE / "__pycache__"
_STAMP = _CACHE / "sources.stamp"


def _sources_stamp() -> str:
    h = hashlib.sha256()
    for f in sorted(_PACKAGE.glob("*.py")):
        st = f.stat()
        h.update(f"{f.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    return h.hexdigest()


def _drop_stale_cache() -> None:
    stamp = _sources_stamp()
    try:
        if _STAMP.read_text() == stamp:
            return
    except OSError:
        pass
    try:
        for f in (*_CACHE.glob("*.nbi"), *_CACHE.glob("*.nbc")):
            f.unlink(missing_ok=True)
        _STAMP.write_text(stamp)
    except OSError:  # a read-only installation: its sources do not change either
        pass


HEARTBEAT_S = 5.0
"""While numba compiles, a line on stderr at least this often [s]."""


class CompileNote(_event.Listener):
    """Word on stderr while numba compiles (a first use, or a cache dropped by an edit).

    The first compile prints what is happening; while compiles run, a line every
    :data:`HEARTBEAT_S` seconds gives the time since the first began. A function loaded from
    the cache is no compile: nothing is printed.
    """

    def __init__(self, stream=None):
        """Lines go to ``stream`` (default ``sys.stderr`` at each line)."""
        self.stream = stream
        self.depth = 0
        self.first = None  # when the first compile began
        self.last = 0.0  # when the last line was printed
        self.lock = threading.Lock()
        self.wake = threading.Event()
        self.thread = None

    def _say(self, text: str) -> None:
        print(f"biped_constraint_env: {text}", file=self.stream or sys.stderr, flush=True)
        self.last = time.monotonic()

    def on_start(self, event) -> None:
        """A compile begins (nested ones counted)."""
        with self.lock:
            self.depth += 1
            if self.first is None:
                self.first = time.monotonic()
                self._say("compiling the simulator core (once per installation: about a "
                          "minute on 2 cores, then cached)")  # fmt: skip
            if self.thread is None:
                self.thread = threading.Thread(target=self._beat, daemon=True,
                                               name="compile-note")  # fmt: skip
                self.thread.start()

    def on_end(self, event) -> None:
        """A compile ends."""
        with self.lock:
            self.depth -= 1

    def _beat(self) -> None:
        while not self.wake.wait(min(0.5, HEARTBEAT_S / 4)):
            with self.lock:
                now = time.monotonic()
                if self.depth > 0 and now - self.last >= HEARTBEAT_S:
                    self._say(f"still compiling: {now - self.first:.0f} s since the first "
                              f"compile began")  # fmt: skip


NOTE = CompileNote()
_event.register("numba:compile", NOTE)

if not os.environ.get("NUMBA_CACHE_DIR"):
    if _CACHE.is_dir():
        _drop_stale_cache()
