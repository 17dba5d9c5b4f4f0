"""Restarts from the env's own states (``restarts``): a start distribution with no recorded motion.

An env with ``restarts=p`` keeps the states it visits at the end of every control period in
which a walking step was completed (and the episode goes on): the latest :data:`POOL_SIZE` of
them, in one pool per env object (all rows of a batched env share it). Each reset then starts,
with probability p, at a state drawn uniformly from the pool (leg A standing, its toe at y = 0,
t = 0, as the env's own starts), else as the env's ``start`` says. While the pool is empty
every reset draws the env's own start. A learner's own walk thus supplies starts just after
each step it completes, where it must take the next: the states a reference-state start would
give, from the policy itself instead of a recording (as restarts from visited states in
exploration; e.g. Ecoffet et al. 2021, Go-Explore).
"""

from __future__ import annotations

import numpy as np

from .model import N_LINKS
from .state import ST_MODE, SimArrays

POOL_SIZE = 4096
"""States a restart pool keeps (the latest)."""


class RestartPool:
    """The latest states after completed steps, and the restarts drawn from them."""

    def __init__(self, fraction: float, size: int = POOL_SIZE):
        """A pool for restarts with probability ``fraction`` (0-1), keeping ``size`` states."""
        self.fraction = float(fraction)
        self.q = np.zeros((size, N_LINKS))
        self.qd = np.zeros((size, N_LINKS))
        self.mode = np.zeros(size, np.int64)
        self.count = 0  # states recorded so far (the pool holds the latest min(count, size))

    def __len__(self) -> int:
        """States in the pool."""
        return min(self.count, self.q.shape[0])

    def record(self, sim: SimArrays, rows: np.ndarray) -> None:
        """Keep the current states of ``rows`` (after a period in which they completed a step)."""
        size = self.q.shape[0]
        for i in rows:
            j = self.count % size
            self.q[j], self.qd[j], self.mode[j] = sim.q[i], sim.qd[i], sim.ist[i, ST_MODE]
            self.count += 1

    def draw(self, rngs) -> tuple[np.ndarray, np.ndarray]:
        """Which of the resets drawing from ``rngs`` restart, and at which pool states.

        Each generator draws one uniform number (whether), and one pool index where it
        restarts; (mask over the resets, pool indices of the restarting ones).
        """
        chosen = np.zeros(len(rngs), bool)
        picks = []
        n = len(self)
        for k, rng in enumerate(rngs):
            if rng.random() < self.fraction and n:
                chosen[k] = True
                picks.append(rng.integers(n))
        return chosen, np.array(picks, np.int64)
