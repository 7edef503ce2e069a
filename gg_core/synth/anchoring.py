"""Garment points carried along by the posed body (barycentric anchors on the nearest body triangle).

The cloth solver needs a target for pinned garment vertices (a skirt's waistband, a dress's top band):
each point is bound once in the rest pose to its closest body triangle (barycentric coordinates of the
foot point plus the offset in the triangle's own frame) and re-placed on the posed triangle every frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .proximity import MeshProximity


@dataclass(frozen=True)
class Anchors:
    triangles: np.ndarray   # [N,3] body vertex indices
    bary: np.ndarray        # [N,3] barycentric coordinates of the foot point
    offset: np.ndarray      # [N,3] point - foot in the triangle frame (edge, binormal, normal)

    def apply(self, body_vertices: np.ndarray) -> np.ndarray:
        """Anchored points for posed bodies [T,V,3] (or [V,3]) -> [T,N,3] (or [N,3])."""
        tri = body_vertices[..., self.triangles, :]                     # [..., N, 3, 3]
        foot = np.einsum("...nkc,nk->...nc", tri, self.bary)
        return foot + np.einsum("...nij,ni->...nj", _frames(tri), self.offset)


def bind(body_vertices: np.ndarray, body_faces: np.ndarray, points: np.ndarray) -> Anchors:
    """Anchor `points` [N,3] to the body surface given in its rest pose (N may be 0: garments without pins)."""
    if len(points) == 0:
        return Anchors(np.zeros((0, 3), np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    foot, _, face = MeshProximity(body_vertices, body_faces).closest(points)
    tris = np.asarray(body_faces, np.int64)[face]
    tri = body_vertices[tris]
    bary = _barycentric(tri, foot)
    offset = np.einsum("nij,nj->ni", _frames(tri), points - foot)
    return Anchors(tris.astype(np.int64), bary, offset)


def _barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Barycentric coordinates [N,3] of points p [N,3] in triangles [N,3,3]."""
    e0, e1, d = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], p - tri[:, 0]
    d00, d01, d11 = (np.einsum("nc,nc->n", x, y) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.einsum("nc,nc->n", d, e0), np.einsum("nc,nc->n", d, e1)
    den = d00 * d11 - d01 * d01 + 1e-30
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.stack([1 - v - w, v, w], axis=1)


def _frames(tri: np.ndarray) -> np.ndarray:
    """Orthonormal frames [..., 3 axes, 3] of triangles [..., 3, 3]: first edge, binormal, normal."""
    e1 = tri[..., 1, :] - tri[..., 0, :]
    n = np.cross(e1, tri[..., 2, :] - tri[..., 0, :])
    e1 = e1 / (np.linalg.norm(e1, axis=-1, keepdims=True) + 1e-12)
    n = n / (np.linalg.norm(n, axis=-1, keepdims=True) + 1e-12)
    return np.stack([e1, np.cross(n, e1), n], axis=-2)
