"""Isotropic remeshing to a target vertex count (Botsch-Kobbelt split/collapse/flip/relax, via gpytoolbox).

Simulation and the Gaussian texture both want near-equilateral triangles of one size. gpytoolbox keeps the
boundary vertices of an open mesh fixed, so closed surfaces are remeshed before they are cut open, and an open
mesh is coarsened by collapsing its short edges (border included) before it is remeshed.
"""
from __future__ import annotations

import numpy as np

from .mesh_graph import compact, vertex_area
from .surface_cut import collapse_short_edges, tidy_border

COARSEN_COLLAPSE = 0.7    # of the target edge: shorter edges, border ones too, collapse before the remesh
SLIVER_EDGE = 0.25        # of the target edge: what the remesher leaves next to the fixed border collapses after


def edge_length_for(area: float, n_vertices: int) -> float:
    """Edge length of an equilateral mesh of `area` with about `n_vertices` vertices (sqrt(3)/2 h^2 each)."""
    return float(np.sqrt(2.0 * area / (np.sqrt(3.0) * max(n_vertices, 1))))


def isotropic_remesh(verts: np.ndarray, faces: np.ndarray, edge_length: float, iterations: int = 10
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(verts, faces) remeshed to edges of about `edge_length`, projected back onto the input surface."""
    import gpytoolbox  # noqa: PLC0415 - compiled extension, only loaded where meshes are remeshed

    v, f = gpytoolbox.remesh_botsch(np.asarray(verts, np.float64), np.asarray(faces, np.int32), iterations,
                                    float(edge_length), True)
    v, f, _ = compact(np.asarray(v, np.float64), np.asarray(f, np.int64))
    return v, f


def remesh_open(verts: np.ndarray, faces: np.ndarray, edge_length: float, iterations: int = 10
                ) -> tuple[np.ndarray, np.ndarray]:
    """An open mesh remeshed to edges of about `edge_length`: the border evened out first (tidy_border), as the
    remesher keeps it fixed, and the slivers it then leaves next to the border collapsed after."""
    verts, faces = tidy_border(verts, faces, edge_length)
    verts, faces = isotropic_remesh(verts, faces, edge_length, iterations)
    return collapse_short_edges(verts, faces, SLIVER_EDGE * edge_length)


def coarsen(verts: np.ndarray, faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """An open or closed mesh remeshed to about `n_vertices` near-equilateral vertices on its own surface.

    The remesher cannot move border vertices, so a fine border would stay fine (and its triangles slivers): edges
    shorter than COARSEN_COLLAPSE of the target length collapse first, border edges to their midpoints, which
    pulls the border inward by a fraction of the fine edge (measured on the demo template, 7470 -> 1000 vertices:
    area 0.528 -> 0.508 m^2)."""
    edge = edge_length_for(float(vertex_area(verts, faces).sum()), n_vertices)
    verts, faces = collapse_short_edges(verts, faces, COARSEN_COLLAPSE * edge)
    return remesh_open(verts, faces, edge)


def edge_lengths(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """[F*3] length of every face side (interior edges counted twice)."""
    return np.linalg.norm(verts[faces] - verts[np.roll(faces, -1, axis=1)], axis=2).ravel()


def triangle_quality(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """[F] 4 sqrt(3) area / sum of squared sides: 1 for equilateral, 0 for degenerate triangles."""
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    sides = (edge_lengths(verts, faces) ** 2).reshape(-1, 3).sum(axis=1)
    return 4.0 * np.sqrt(3.0) * area / np.maximum(sides, 1e-300)
