"""Starting the package's commands as child processes in tests."""

from __future__ import annotations

import signal


def default_sigint() -> None:
    """``preexec_fn``: Ctrl-C's default in the child, however pytest was started.

    A shell starts a background job with SIGINT ignored, and a child inherits that: Python
    then installs no KeyboardInterrupt handler, and a test that interrupts a command would
    find it running on.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)
