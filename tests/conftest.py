"""Shared fixtures: small captures written in the product's capture layout, and the synthetic tiny preset."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gg_core.capture.cameras import look_at, save_cameras
from gg_core.geometry.meshio import write_ply
from gg_core.synth.generate import SynthRequest, generate
from gg_core.synth.presets import get_preset


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Slow tests first, the Blender ones (slow and bpy) before the rest. Why: xdist hands tests out in this order,
    so the longest start while the many short ones can still fill the other worker, and the run does not end on
    one long test with one worker waiting. Stable: within each kind the collection order stays."""
    items.sort(key=lambda item: (item.get_closest_marker("slow") is None, item.get_closest_marker("bpy") is None))


def write_small_capture(root: Path, n_cams: int = 3, n_frames: int = 3, size: tuple[int, int] = (40, 30),
                        sequences: tuple[str, ...] = ("seq0",)) -> Path:
    """A tiny but complete capture: a ring of cameras around an octahedron 'body' moving up over time."""
    rng = np.random.default_rng(0)
    w, h = size
    octa_v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float) * 0.3
    octa_f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    for seq in sequences:
        cams = {}
        for i in range(n_cams):
            a = 2 * np.pi * i / n_cams
            eye = np.array([2.5 * np.sin(a), 1.0, 2.5 * np.cos(a)])
            cams[f"cam{i:02d}"] = look_at(f"cam{i:02d}", eye, np.array([0, 1.0, 0]), 50, w, h, index=i)
        save_cameras(root / seq / "cameras.json", cams)
        for cid in cams:
            for k in range(n_frames):
                for kind in ("rgb_images", "garment_masks", "foreground_masks"):
                    folder = root / seq / cid / kind
                    folder.mkdir(parents=True, exist_ok=True)
                    if kind == "rgb_images":
                        img = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
                    else:
                        img = np.zeros((h, w), np.uint8)
                        img[h // 3: 2 * h // 3, w // 3: 2 * w // 3] = 255
                    Image.fromarray(img).save(folder / f"{k:06d}.png")
        for k in range(n_frames):
            write_ply(root / seq / "body" / f"{k:06d}.ply", octa_v + [0, 1.0 + 0.01 * k, 0], octa_f)
    return root


@pytest.fixture
def small_capture(tmp_path: Path) -> Path:
    return write_small_capture(tmp_path / "capture")


@pytest.fixture
def capture_writer():
    """write_small_capture itself, for tests that need other sizes or several sequences."""
    return write_small_capture


def generate_tiny(root: Path, **options: object) -> Path:
    """Generate the tiny preset under `root` (skirt, seed 0, effect none unless overridden); return the report.

    Blender cloth + Cycles, about a minute: stage tests share one capture through `tiny_capture`.
    """
    return generate(SynthRequest(preset=get_preset("tiny"), out=root, progress="none", **options))


@pytest.fixture(scope="session")
def tiny_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny synthetic capture (6 cameras 72x96, 2 sequences x 8 frames, skirt), generated once per test run
    and shared by the xdist workers (the first one generates under a lock; tests only read it)."""
    from filelock import FileLock

    shared = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        shared = shared.parent  # common to all workers of this run
    root = shared / "tiny_capture"
    with FileLock(str(root) + ".lock"):
        if not (root / "reports" / "synth.json").is_file():
            generate_tiny(root)
    return root


EXTENSION_ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def extension_package():
    """The repository root imported as the extension package `gaussian_garments`, as Blender imports it.

    The add-on's relative imports (`from ..gg_core ...`) need it; its bpy-free modules work without bpy.
    """
    import importlib.util
    import sys

    name = "gaussian_garments"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, EXTENSION_ROOT / "__init__.py",
                                                      submodule_search_locations=[str(EXTENSION_ROOT)])
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


@pytest.fixture
def blender(extension_package):
    """bpy with an empty factory-settings scene and the add-on registered (unregistered afterwards)."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    extension_package.register()
    yield bpy
    extension_package.unregister()
