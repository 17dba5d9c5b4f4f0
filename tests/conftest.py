"""Shared fixtures: the paper's robot, a seeded RNG, and one sample state per model."""

from __future__ import annotations

import numpy as np
import pytest

from biped_constraint_env.model import paper_biped

TABLE2_NM = np.array(
    [
        [10.0, 120.0, 35.0, 80.0, 0.0],
        [40.0, 0.0, 30.0, -30.0, -5.0],
        [-120.0, -70.0, 55.0, -30.0, -10.0],
        [-120.0, -70.0, 55.0, -30.0, -10.0],
    ]
)
"""Paper Table 2, in the paper's signs (rows: models 1-4)."""

STANCE_POSTURE = np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])
"""A model-1 posture: stance leg upright, swing leg back and bent, swing foot flat in the air."""


@pytest.fixture(scope="session")
def params():
    return paper_biped()


@pytest.fixture(scope="session")
def chain(params):
    return params.chain(0)


@pytest.fixture
def rng():
    return np.random.default_rng(0)
