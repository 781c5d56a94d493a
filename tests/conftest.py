"""Shared fixtures: the iiwa (A3 locked and free), the human model, random inputs."""

from __future__ import annotations

import numpy as np
import pytest

import qpavoid


@pytest.fixture(scope="session")
def robot():
    return qpavoid.load_robot("iiwa14")


@pytest.fixture(scope="session")
def robot7():
    return qpavoid.load_robot("iiwa14", locked=())


@pytest.fixture(scope="session")
def human():
    return qpavoid.KinectHuman()


def random_q(rng: np.random.Generator, robot, margin: float = 0.05) -> np.ndarray:
    """Uniform joint angles inside the position limits (rad)."""
    return rng.uniform(robot.q_min + margin, robot.q_max - margin)
