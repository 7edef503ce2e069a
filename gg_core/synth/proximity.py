"""Closest points on a triangle mesh and signed distances, numpy + scipy only.

Candidates are the triangles around the k nearest mesh vertices of each query (exact for query points
near a reasonably uniform mesh such as the body, which is all garments and anchors need).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


class MeshProximity:
    """Closest-point queries against one triangle mesh; `update` swaps in posed vertices, same topology."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, k: int = 6) -> None:
        self.faces = np.asarray(faces, np.int64)
        self.k = k
        # vertex -> incident faces as a padded table (padding repeats a real incident face)
        n_v = int(self.faces.max()) + 1
        vert = self.faces.ravel()
        face = np.repeat(np.arange(len(self.faces)), 3)
        order = np.argsort(vert, kind="stable")
        vert, face = vert[order], face[order]
        degree = np.bincount(vert, minlength=n_v)
        start = np.r_[0, np.cumsum(degree)[:-1]]
        slot = np.arange(len(vert)) - start[vert]
        table = np.repeat(face[start][:, None] if len(face) else np.zeros((n_v, 1), np.int64), degree.max(), 1)
        table[vert, slot] = face
        self._vertex_faces = table
        self.update(vertices)

    def update(self, vertices: np.ndarray) -> None:
        self.vertices = np.asarray(vertices, np.float64)
        self._tree = cKDTree(self.vertices)
        tri = self.vertices[self.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.face_normals = n / (np.linalg.norm(n, axis=1, keepdims=True) + 1e-20)

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(closest points [N,3], distances [N], face index [N]) for query points [N,3]."""
        points = np.asarray(points, np.float64)
        _, near = self._tree.query(points, k=min(self.k, len(self.vertices)))  # small meshes: k <= V
        cand = self._vertex_faces[near].reshape(len(points), -1)              # [N, k * max degree]
        tri = self.vertices[self.faces[cand.ravel()]]
        q = np.repeat(points, cand.shape[1], axis=0)
        foot = closest_on_triangles(q, tri[:, 0], tri[:, 1], tri[:, 2]).reshape(len(points), -1, 3)
        d2 = ((foot - points[:, None]) ** 2).sum(-1)
        best = d2.argmin(axis=1)
        rows = np.arange(len(points))
        return foot[rows, best], np.sqrt(d2[rows, best]), cand[rows, best]

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance to the surface, negative inside (sign from the closest face's outward normal)."""
        foot, dist, face = self.closest(points)
        side = np.einsum("nc,nc->n", np.asarray(points) - foot, self.face_normals[face])
        return np.where(side < 0, -dist, dist)


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Closest point of each triangle (a, b, c) [N,3] to p [N,3] (Voronoi-region cases, vectorized)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp, cp = p - b, p - c
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denom = va + vb + vc
    with np.errstate(divide="ignore", invalid="ignore"):
        v = vb / denom
        w = vc / denom
        out = a + ab * v[:, None] + ac * w[:, None]                        # inside the face
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    cases = [  # later entries take precedence, so vertex regions come last
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * t_ab[:, None]),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * t_ac[:, None]),
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + (c - b) * t_bc[:, None]),
        ((d1 <= 0) & (d2 <= 0), a),
        ((d3 >= 0) & (d4 <= d3), b),
        ((d6 >= 0) & (d5 <= d6), c),
    ]
    for mask, value in cases:
        out = np.where(mask[:, None], value, out)
    return out


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.einsum("nc,nc->n", x, y)
