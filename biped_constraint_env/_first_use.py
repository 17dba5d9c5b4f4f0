"""Say so when the compiled core has no cache yet: its first use compiles it (once)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

_CACHE = Path(__file__).resolve().parent / "__pycache__"

if not os.environ.get("NUMBA_CACHE_DIR") and not any(_CACHE.glob("*.nbi")):
    print(
        "biped_constraint_env: no compiled cache yet; the first simulation compiles the core "
        "(30-60 s, once per installation)",
        file=sys.stderr,
        flush=True,
    )
