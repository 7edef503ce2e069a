"""Mesh connectivity derived once from the triangle list: edges, hinges (dihedral stencils), adjacency.

Cloth energies live on these sets (stretching on faces, bending on hinges, rest lengths on edges) and the
simulator's sparse Hessian pattern is their union, so they are computed here once and shared. Numpy only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Topology:
    """Connectivity of a triangle mesh with a fixed vertex count.

    `face_edges[f, k]` is the edge joining corners k and k+1 of face f (k = 0, 1, 2).
    A hinge is an interior edge with exactly two faces: `hinges[h] = (e0, e1, o0, o1)` where face A
    `hinge_faces[h, 0]` winds e0 -> e1 -> o0 and face B winds e1 -> e0 -> o1 on a consistently
    oriented mesh, so both face normals point to the same side.
    """

    n_vertices: int
    faces: np.ndarray        # [F,3] int64
    edges: np.ndarray        # [E,2] int64, i < j
    face_edges: np.ndarray   # [F,3] int64
    hinges: np.ndarray       # [H,4] int64
    hinge_edges: np.ndarray  # [H] int64
    hinge_faces: np.ndarray  # [H,2] int64
    edge_face_count: np.ndarray  # [E] int64: 1 on the boundary, 2 inside, more on non-manifold edges

    @property
    def boundary_vertices(self) -> np.ndarray:
        """[V] bool: vertices on an edge with a single face."""
        mask = np.zeros(self.n_vertices, bool)
        mask[self.edges[self.edge_face_count == 1].ravel()] = True
        return mask


def build_topology(faces: np.ndarray, n_vertices: int) -> Topology:
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    n_faces = len(faces)
    corner_a = faces.reshape(-1)                       # corner k of face f at 3f+k
    corner_b = np.roll(faces, -1, axis=1).reshape(-1)  # corner k+1
    lo, hi = np.minimum(corner_a, corner_b), np.maximum(corner_a, corner_b)
    keys = lo * n_vertices + hi
    uniq, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    edges = np.stack([uniq // n_vertices, uniq % n_vertices], axis=1)
    face_edges = inverse.reshape(n_faces, 3)

    # Half-edges of interior edges with exactly two faces become hinges.
    order = np.argsort(inverse, kind="stable")
    sorted_edge = inverse[order]
    first = np.flatnonzero(np.r_[True, sorted_edge[1:] != sorted_edge[:-1]])
    two = counts[sorted_edge[first]] == 2
    he_a, he_b = order[first[two]], order[first[two] + 1]   # half-edge ids (3f+k) of both faces
    face_a, face_b = he_a // 3, he_b // 3
    e0, e1 = corner_a[he_a], corner_b[he_a]
    o0 = faces[face_a, (he_a % 3 + 2) % 3]
    o1 = faces[face_b, (he_b % 3 + 2) % 3]
    hinges = np.stack([e0, e1, o0, o1], axis=1)
    return Topology(n_vertices=int(n_vertices), faces=faces, edges=edges, face_edges=face_edges,
                    hinges=hinges, hinge_edges=sorted_edge[first[two]], hinge_faces=np.stack([face_a, face_b], 1),
                    edge_face_count=counts)


def vertex_faces(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR (offsets [V+1], face ids) of the faces around each vertex."""
    faces = np.asarray(faces, np.int64)
    corners = faces.reshape(-1)
    order = np.argsort(corners, kind="stable")
    offsets = np.zeros(n_vertices + 1, np.int64)
    np.cumsum(np.bincount(corners, minlength=n_vertices), out=offsets[1:])
    return offsets, order // 3


def face_areas(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    tri = verts[faces]
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def vertex_areas(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Lumped (barycentric) area per vertex: a third of each incident face."""
    return np.bincount(faces.reshape(-1), np.repeat(face_areas(verts, faces) / 3.0, 3), minlength=len(verts))
