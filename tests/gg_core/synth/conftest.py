"""Synthetic tiny captures for the generator's own tests; `tiny_capture` itself is shared from tests/conftest.py."""
from __future__ import annotations

from pathlib import Path

import pytest

from ...conftest import generate_tiny  # the shared generator (test_generate imports it from here)


@pytest.fixture(scope="session")
def tiny_wind_truth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Same seed as `tiny_capture`, wind on, ground truth only (no renders)."""
    root = tmp_path_factory.mktemp("synth") / "tiny_wind"
    generate_tiny(root, effect="wind", render=False)
    return root
