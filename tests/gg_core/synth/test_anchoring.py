"""Anchoring garment points to the body surface."""
from __future__ import annotations

import numpy as np
import trimesh

from gg_core.synth.anchoring import bind


def test_bind_with_no_points_applies_to_no_points() -> None:
    """Garments without pinned vertices (the T-shirt) anchor nothing, for any number of frames."""
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    anchors = bind(verts, np.array([[0, 1, 2]]), np.zeros((0, 3)))
    assert anchors.apply(np.repeat(verts[None], 4, 0)).shape == (4, 0, 3)


def test_anchored_points_follow_a_rigid_motion() -> None:
    mesh = trimesh.creation.icosphere(2)
    points = mesh.vertices[:20] * 1.05
    anchors = bind(mesh.vertices, mesh.faces, points)
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    moved = anchors.apply(mesh.vertices @ rot.T + [1, 2, 3])
    assert np.allclose(moved, points @ rot.T + [1, 2, 3], atol=1e-9)
