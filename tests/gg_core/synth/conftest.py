"""Synthetic tiny captures, generated once per test session (Blender cloth + Cycles, about a minute).

`generate_tiny(root, **options)` is the helper the lead can wrap as a shared `tiny_capture` fixture in
tests/conftest.py for other stages' tests.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from gg_core.synth.generate import SynthRequest, generate
from gg_core.synth.presets import get_preset


def generate_tiny(root: Path, **options: object) -> Path:
    """Generate the tiny preset under `root` (skirt, seed 0, effect none unless overridden); return the report."""
    return generate(SynthRequest(preset=get_preset("tiny"), out=root, progress="none", **options))


@pytest.fixture(scope="session")
def tiny_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("synth") / "tiny"
    generate_tiny(root)
    return root


@pytest.fixture(scope="session")
def tiny_wind_truth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Same seed as `tiny_capture`, wind on, ground truth only (no renders)."""
    root = tmp_path_factory.mktemp("synth") / "tiny_wind"
    generate_tiny(root, effect="wind", render=False)
    return root
