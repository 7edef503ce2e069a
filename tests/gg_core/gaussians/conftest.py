"""Fixtures for the Gaussian tests: the per-pixel reference renderer and its random scenes."""
from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import pytest


def _load_reference() -> ModuleType:
    # tests run with --import-mode=importlib (no sys.path entry), so load the helper by path
    spec = importlib.util.spec_from_file_location("gg_tests_gaussians_reference",
                                                  Path(__file__).with_name("reference.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_REFERENCE = _load_reference()


@pytest.fixture(scope="session")
def reference() -> ModuleType:
    """tests/gg_core/gaussians/reference.py: reference_render, random_scene, project_one."""
    return _REFERENCE
