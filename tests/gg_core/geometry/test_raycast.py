"""Embree ray casting: distances, misses, segment blocking, and that Embree really is the engine."""
from __future__ import annotations

import numpy as np
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

from gg_core.geometry.raycast import RayCaster


def _square(z: float, half: float = 1.0):
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def test_uses_embree():
    caster = RayCaster([_square(0.0)])
    assert isinstance(caster.intersector, RayMeshIntersector)
    assert trimesh.ray.has_embree


def test_first_hit_distance_over_several_meshes():
    caster = RayCaster([_square(2.0, half=2.0), _square(1.0, half=0.5)])
    origins = np.zeros((3, 3))
    # straight ahead: the small near square; slanted: passes beside it (x = 0.7 at z = 1) onto the far one
    dirs = np.array([[0, 0, 1.0], [1.4 / np.hypot(1.4, 2), 0, 2 / np.hypot(1.4, 2)], [0, 0, -1.0]])
    d = caster.first_hit_distance(origins, dirs)
    assert np.allclose(d[:2], [1.0, np.hypot(1.4, 2)], atol=1e-5) and np.isinf(d[2])


def test_segment_blocked_only_before_the_target():
    caster = RayCaster([_square(1.0)])
    targets = np.array([[0, 0, 0.5], [0, 0, 1.0], [0, 0, 1.5], [3, 0, 1.5]])
    assert caster.segment_blocked(np.zeros(3), targets).tolist() == [False, False, True, False]
