"""Ctrl-C while a command of this package is still starting: one line, no traceback.

A command's ``main`` turns Ctrl-C into one line (:func:`training.plumbing.common.command`),
but its module's imports (torch, numba's cache) run before ``main``: a Ctrl-C there would print
a traceback. Imported first by each command module; when that module is the program being
run (``python -m training.ppo.train``, whose ``sys.argv[0]`` is the module's file), an
uncaught KeyboardInterrupt is shown as one line. Imported as a library, nothing changes.
Imports nothing but the standard library.
"""

from __future__ import annotations

import os
import sys

_PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _is_our_command(argv0: str) -> bool:
    path = os.path.abspath(argv0)
    return path.endswith(".py") and os.path.commonpath([path, _PACKAGE_ROOT]) == _PACKAGE_ROOT


def _hook(kind, value, tb) -> None:
    if issubclass(kind, KeyboardInterrupt):
        name = os.path.splitext(os.path.basename(sys.argv[0]))[0]
        print(f"\n{name}: interrupted while starting; nothing was written", file=sys.stderr,
              flush=True)  # fmt: skip
        return
    sys.__excepthook__(kind, value, tb)


if sys.argv and sys.argv[0] and _is_our_command(sys.argv[0]):
    sys.excepthook = _hook
