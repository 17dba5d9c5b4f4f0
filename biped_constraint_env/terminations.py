"""Early terminations for learning, as a named list: each ends rows after a period.

The strict checks' out-of-model events and the fall height end an episode inside the compiled
period; the terminations here are the learning task's own, chosen by name from the
``termination`` settings (:data:`TERMINATIONS`) and run by the core in that order. One is a
class built from the core (:class:`~.core.EnvCore`), called with the period's ``terminated``
flags (set in place) and the rows it skipped.
"""

from __future__ import annotations

import numpy as np


class ModelTime:
    """``termination={"max_model_time_s": T}``: a contact phase held longer than T [s].

    By the contact clock; with a command, only while it is not zero (standing holds a contact
    phase). The reason is ``model_time``.
    """

    def __init__(self, core):
        """For ``core``'s clock, its commands (if any) and the limit."""
        self.clock, self.commands = core.clock, core.commands
        self.limit_s = core.settings.termination.max_model_time_s

    def __call__(self, terminated: np.ndarray, skip) -> None:
        """Set ``terminated`` where a stepped row held its contact phase too long."""
        held = self.clock.model_time_s() > self.limit_s + 1e-9
        if self.commands is not None:
            held &= self.commands.v != 0.0
        if skip is not None:
            held[skip] = False
        terminated |= held


TERMINATIONS = {"max_model_time_s": ModelTime}
"""The learning task's terminations by their ``termination`` setting, in the order they run."""


def terminations(core) -> list:
    """The terminations ``core``'s settings switch on (a setting not None), in order."""
    t = core.settings.termination
    return [make(core) for key, make in TERMINATIONS.items() if getattr(t, key) is not None]
