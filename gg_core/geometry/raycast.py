"""Ray casting against triangle meshes with Embree (embreex through trimesh).

Used for Gaussian visibility in layered outfits (is the ray from the camera to a surface point
blocked by the body or another garment?) and by any stage that needs first-hit queries.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np


class RayCaster:
    """An Embree BVH over one or more triangle meshes (concatenated into one scene)."""

    def __init__(self, meshes: Sequence[tuple[np.ndarray, np.ndarray]]) -> None:
        import trimesh  # noqa: PLC0415
        from trimesh.ray.ray_pyembree import RayMeshIntersector  # noqa: PLC0415 - fails loudly without embreex

        verts, faces, offset = [], [], 0
        for v, f in meshes:
            verts.append(np.asarray(v, np.float64))
            faces.append(np.asarray(f, np.int64) + offset)
            offset += len(v)
        self.mesh = trimesh.Trimesh(np.concatenate(verts), np.concatenate(faces), process=False)
        self.intersector = RayMeshIntersector(self.mesh)

    def first_hit_distance(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """[R] distance along each unit direction to the first triangle hit (inf where none)."""
        origins = np.asarray(origins, np.float64).reshape(-1, 3)
        directions = np.asarray(directions, np.float64).reshape(-1, 3)
        dist = np.full(len(origins), np.inf)
        if len(origins) == 0:
            return dist
        locations, ray_ids, _ = self.intersector.intersects_location(origins, directions, multiple_hits=False)
        dist[ray_ids] = np.linalg.norm(locations - origins[ray_ids], axis=1)
        return dist

    def segment_blocked(self, origins: np.ndarray, targets: np.ndarray, eps: float = 1e-4) -> np.ndarray:
        """[R] True where a triangle lies on the segment origin -> target, more than `eps` before the target."""
        origins = np.broadcast_to(np.asarray(origins, np.float64), np.shape(targets))
        delta = np.asarray(targets, np.float64) - origins
        length = np.linalg.norm(delta, axis=1)
        direction = delta / np.maximum(length, 1e-300)[:, None]
        return self.first_hit_distance(origins, direction) < length - eps
