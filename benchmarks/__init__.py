"""Speed and accuracy studies (never asserted in tests)."""

import training.plumbing.interrupts  # noqa: F401 (first: Ctrl-C while a command starts, one line)
