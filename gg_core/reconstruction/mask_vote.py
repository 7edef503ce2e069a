"""Per-vertex garment vote: among the cameras that see a surface point unoccluded, how much of it lies in the
garment mask. Garment masks show only the visible garment, so a vote over visible cameras (not a carve with the
garment masks) is what separates garment from body on the person's hull.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..capture.cameras import Camera
from ..geometry.raycast import RayCaster
from .mesh_graph import vertex_normals
from .visual_hull import bilinear

MIN_COSINE = 0.1   # views more grazing than ~84 degrees do not vote


def garment_vote(verts: np.ndarray, faces: np.ndarray, cameras: Sequence[Camera],
                 garment_masks: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(vote [V] in [0, 1], weight [V]): the cosine-weighted mean garment-mask value at each vertex's projection
    over the cameras that see the vertex's front side unblocked by the mesh itself; weight 0 where none does."""
    verts = np.asarray(verts, np.float64)
    normals = vertex_normals(verts, faces)
    edge = np.linalg.norm(verts[faces[:, 0]] - verts[faces[:, 1]], axis=1).mean()
    lifted = verts + 0.5 * edge * normals      # ray start just off the surface, so it does not hit its own faces
    caster = RayCaster([(verts, faces)])
    total = np.zeros(len(verts))
    weight = np.zeros(len(verts))
    for cam, mask in zip(cameras, garment_masks):
        to_cam = cam.center - verts
        dist = np.linalg.norm(to_cam, axis=1)
        cos = np.einsum("ij,ij->i", normals, to_cam) / np.maximum(dist, 1e-12)
        uv, z = cam.project(verts)
        ok = (cos > MIN_COSINE) & (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width) & \
             (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height)
        idx = np.flatnonzero(ok)
        idx = idx[~caster.segment_blocked(np.broadcast_to(cam.center, (len(idx), 3)), lifted[idx], eps=0.0)]
        value = bilinear(np.asarray(mask, np.float64), uv[idx, 0], uv[idx, 1])
        total[idx] += cos[idx] * value
        weight[idx] += cos[idx]
    vote = np.where(weight > 0, total / np.maximum(weight, 1e-12), 0.0)
    return vote, weight
