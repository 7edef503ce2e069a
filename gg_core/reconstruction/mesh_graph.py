"""Scalar fields on a triangle mesh's vertex graph: normals, areas, smoothing, connected pieces."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components


def vertex_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """[V, 3] unit normals: area-weighted sums of the face normals around each vertex."""
    tri = verts[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vn = np.zeros_like(verts, dtype=np.float64)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)


def vertex_area(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """[V] a third of the area of the faces around each vertex (sums to the mesh area)."""
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return np.bincount(faces.ravel(), np.repeat(area / 3.0, 3), minlength=len(verts))


def adjacency(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """Symmetric 0/1 vertex adjacency of the mesh edges."""
    i = faces.ravel()
    j = np.roll(faces, -1, axis=1).ravel()
    a = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices)).tocsr()
    a = a + a.T
    a.data[:] = 1.0
    return a


def smooth(values: np.ndarray, adj: sp.csr_matrix, iterations: int, weight: float = 0.5) -> np.ndarray:
    """Uniform Laplacian smoothing: each step moves a value `weight` of the way to its neighbours' mean."""
    degree = np.maximum(np.asarray(adj.sum(axis=1)).ravel(), 1.0)
    out = np.asarray(values, np.float64).copy()
    for _ in range(iterations):
        out = (1 - weight) * out + weight * (adj @ out) / degree
    return out


def smoothed_normals(normals: np.ndarray, adj: sp.csr_matrix, iterations: int) -> np.ndarray:
    """[V, 3] unit normals after `iterations` smoothing steps: the way a patch of surface faces, without the tilt of
    wrinkles smaller than the patch (which camera sees a point is a property of the patch around it)."""
    out = np.stack([smooth(normals[:, k], adj, iterations) for k in range(3)], axis=1)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)


def genus(faces: np.ndarray) -> int:
    """Genus of a connected manifold triangle mesh from its Euler characteristic and border loops."""
    from .surface_cut import border_loops  # noqa: PLC0415 - surface_cut builds on this module

    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1),
                      axis=0)
    euler = len(np.unique(faces)) - len(edges) + len(faces)
    return (2 - euler - border_loops(faces)) // 2


def vertex_components(adj: sp.csr_matrix, members: np.ndarray) -> np.ndarray:
    """[V] label of the connected piece of each member vertex within the member subgraph, -1 elsewhere."""
    labels = np.full(adj.shape[0], -1, np.int64)
    idx = np.flatnonzero(members)
    if len(idx):
        _, sub = connected_components(adj[idx][:, idx], directed=False)
        labels[idx] = sub
    return labels


def face_components(faces: np.ndarray) -> np.ndarray:
    """[F] label of each face's edge-connected piece."""
    n = len(faces)
    if n == 0:
        return np.zeros(0, np.int64)
    lo = np.minimum(faces, np.roll(faces, -1, axis=1)).ravel()
    hi = np.maximum(faces, np.roll(faces, -1, axis=1)).ravel()
    key = lo * (int(faces.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    same = np.flatnonzero(key[order][1:] == key[order][:-1])
    fa, fb = order[same] // 3, order[same + 1] // 3
    graph = sp.coo_matrix((np.ones(len(fa)), (fa, fb)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def compact(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drop unreferenced vertices: (verts, faces, old index of each kept vertex)."""
    used = np.unique(faces)
    remap = np.full(len(verts), -1, np.int64)
    remap[used] = np.arange(len(used))
    return verts[used], remap[faces], used
