"""Shared fixtures: the paper's robot, a seeded RNG, and one sample state per model."""

from __future__ import annotations

import os

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


@pytest.fixture(scope="session", autouse=True)
def sb3_log_folder(tmp_path_factory):
    """SB3's default logger folder inside pytest's temporary tree.

    A plain ``PPO(...).learn()`` with no ``tensorboard_log`` makes an (empty) folder
    ``SB3-<date>`` under the system's temporary directory unless ``SB3_LOGDIR`` names one.
    """
    old = os.environ.get("SB3_LOGDIR")
    os.environ["SB3_LOGDIR"] = str(tmp_path_factory.mktemp("sb3_logs"))
    yield
    if old is None:
        os.environ.pop("SB3_LOGDIR", None)
    else:
        os.environ["SB3_LOGDIR"] = old


@pytest.fixture(scope="session")
def params():
    return paper_biped()


@pytest.fixture(scope="session")
def chain(params):
    return params.chain(0)


@pytest.fixture
def rng():
    return np.random.default_rng(0)
