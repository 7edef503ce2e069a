"""Fixtures of the physics tests (helpers live in physics_helpers.py, importable from these tests)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from physics_helpers import random_cloth, random_step  # noqa: E402

from gg_core.physics.cloth import Cloth  # noqa: E402
from gg_core.physics.terms import StepInputs  # noqa: E402


@pytest.fixture
def cloth() -> Cloth:
    return random_cloth()


@pytest.fixture
def state(cloth: Cloth) -> tuple[np.ndarray, StepInputs]:
    """(x, step): end positions to evaluate at and the step inputs."""
    rng = np.random.default_rng(2)
    x_prev = cloth.template + rng.normal(0, 0.01, cloth.template.shape)
    return cloth.template + rng.normal(0, 0.02, cloth.template.shape), random_step(cloth, x_prev)
