"""Ctrl-C while a command of this package is still starting: one line, no traceback.

A command's ``main`` turns Ctrl-C into one line (:func:`training.plumbing.common.command`),
but its module's imports (torch, numba's cache) run before ``main``: a Ctrl-C there would print
a traceback. The ``training`` and ``benchmarks`` packages import this module first, so it runs
before any command module's own imports. When the program is one of the packages' commands
(``python -m training.ppo.train``: ``sys.orig_argv`` names the module), an uncaught
KeyboardInterrupt is shown as one line naming the command, and Ctrl-C is recorded
(:func:`received`) before it is raised: Python drops a KeyboardInterrupt raised inside a
finaliser or a callback it runs on its own ("Exception ignored in ..."), and a command's
output must not be written as if nothing had happened (``command_output`` checks it before it
moves anything in). Imported as a library, nothing changes. Imports nothing but the standard
library.
"""

from __future__ import annotations

import signal
import sys

PACKAGES = ("training", "benchmarks")
"""The packages whose modules are commands (``python -m PACKAGE.…``)."""


def command_name(orig_argv: list[str]) -> str | None:
    """The command's short name ("train" for ``python -m training.ppo.train``), or None.

    None unless the interpreter was started with ``-m`` on a module of :data:`PACKAGES`. The
    interpreter's options are read as Python reads them: the first of ``-c``, ``-m``, ``-`` or
    a script ends them (``-X`` and ``-W`` take a value).
    """
    args = iter(orig_argv[1:])
    for arg in args:
        if arg in ("-X", "-W"):
            next(args, None)
        elif arg.startswith("-m"):
            module = arg[2:] or next(args, "")
            if module.split(".")[0] not in PACKAGES:
                return None
            return module.rsplit(".", 1)[-1]
        elif arg.startswith("-c") or arg == "-" or not arg.startswith("-"):
            return None
    return None


def _hook(kind, value, tb) -> None:
    if issubclass(kind, KeyboardInterrupt):
        print(f"\n{_NAME}: interrupted while starting; nothing was written", file=sys.stderr,
              flush=True)  # fmt: skip
        return
    sys.__excepthook__(kind, value, tb)


_RECEIVED = False


def received() -> bool:
    """Whether Ctrl-C (SIGINT) reached this command, even where Python dropped its exception."""
    return _RECEIVED


def _on_sigint(signum, frame) -> None:
    global _RECEIVED
    _RECEIVED = True
    signal.default_int_handler(signum, frame)  # raises KeyboardInterrupt


_NAME = command_name(getattr(sys, "orig_argv", []))
if _NAME is not None:
    sys.excepthook = _hook
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not when ignored
        signal.signal(signal.SIGINT, _on_sigint)
