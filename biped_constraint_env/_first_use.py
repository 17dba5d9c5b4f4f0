"""The compiled cache: cleared when any source changed, and a note before a first compile.

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
from pathlib import Path

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


if not os.environ.get("NUMBA_CACHE_DIR"):
    if _CACHE.is_dir():
        _drop_stale_cache()
    if not any(_CACHE.glob("*.nbi")):
        print(
            "biped_constraint_env: no compiled cache yet; the first simulation compiles the core "
            "(30-60 s, once per installation)",
            file=sys.stderr,
            flush=True,
        )
