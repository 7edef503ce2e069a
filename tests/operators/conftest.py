"""Helpers for operator tests: the Y-up → Z-up map and the vertices Blender evaluates (modifiers applied)."""
from __future__ import annotations

from typing import Callable

import numpy as np
import pytest


@pytest.fixture
def z_up() -> Callable[[np.ndarray], np.ndarray]:
    return lambda points: np.stack([points[:, 0], -points[:, 2], points[:, 1]], axis=1)


@pytest.fixture
def evaluated_vertices(blender) -> Callable:
    """Vertex positions of an object after its modifiers (e.g. the Mesh Cache) at the current frame."""
    def read(obj) -> np.ndarray:
        evaluated = obj.evaluated_get(blender.context.evaluated_depsgraph_get())
        mesh = evaluated.to_mesh()
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        evaluated.to_mesh_clear()
        return co.reshape(-1, 3)
    return read
