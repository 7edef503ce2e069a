"""Cut a closed surface open along a level of a per-vertex field, and keep the main pieces.

The cut follows the field's level line through the triangles (not the mesh edges), so the garment's border is
smooth; a vertex that lies within SNAP of an edge's length from the crossing is moved onto it instead of
splitting the edge, which avoids sliver triangles along the border.
"""
from __future__ import annotations

import numpy as np

from .mesh_graph import compact, face_components

SNAP = 0.2


def cut_at_level(verts: np.ndarray, faces: np.ndarray, values: np.ndarray, level: float = 0.5
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(verts, faces) of the part of the surface where values >= level, bounded by the level line."""
    verts = np.asarray(verts, np.float64).copy()
    values = np.asarray(values, np.float64).copy()
    faces = np.asarray(faces, np.int64)
    _snap(verts, values, faces, level)
    inside = values >= level
    n_in = inside[faces].sum(axis=1)
    keep = [faces[n_in == 3]]
    crossing_faces = faces[(n_in > 0) & (n_in < 3)]
    new_points: list[np.ndarray] = []
    split: dict[tuple[int, int], int] = {}

    def crossing(a: int, b: int) -> int:
        key = (min(a, b), max(a, b))
        if key not in split:
            t = (level - values[a]) / (values[b] - values[a])
            split[key] = len(verts) + len(new_points)
            new_points.append(verts[a] + t * (verts[b] - verts[a]))
        return split[key]

    pieces = []
    for face in crossing_faces:
        polygon = []
        for k in range(3):
            a, b = int(face[k]), int(face[(k + 1) % 3])
            if inside[a]:
                polygon.append(a)
            if inside[a] != inside[b] and values[a] != level and values[b] != level:
                polygon.append(crossing(a, b))
        if len(polygon) == 3:
            pieces.append(polygon)
        elif len(polygon) == 4:
            pieces.extend(_split_quad(polygon, verts, new_points))
    if pieces:
        keep.append(np.asarray(pieces, np.int64))
    if new_points:
        verts = np.concatenate([verts, np.asarray(new_points)])
    out_faces = np.concatenate(keep) if keep else np.zeros((0, 3), np.int64)
    out_verts, out_faces, _ = compact(verts, out_faces)
    return out_verts, out_faces


def _snap(verts: np.ndarray, values: np.ndarray, faces: np.ndarray, level: float) -> None:
    """Move vertices that are very near a level crossing on one of their edges onto it (in place)."""
    a = faces.ravel()
    b = np.roll(faces, -1, axis=1).ravel()
    cross = (values[a] - level) * (values[b] - level) < 0
    a, b = a[cross], b[cross]
    t = (level - values[a]) / (values[b] - values[a])          # crossing at a + t (b - a)
    # each crossing may snap its nearer end; a vertex takes its nearest crossing
    end = np.where(t < 0.5, a, b)
    other = np.where(t < 0.5, b, a)
    frac = np.where(t < 0.5, t, 1 - t)
    near = frac < SNAP
    end, other, frac = end[near], other[near], frac[near]
    order = np.argsort(frac)
    end, other, frac = end[order], other[order], frac[order]
    first = np.unique(end, return_index=True)[1]
    target = verts[end[first]] + frac[first, None] * (verts[other[first]] - verts[end[first]])
    verts[end[first]] = target
    values[end[first]] = level


def _split_quad(polygon: list[int], verts: np.ndarray, new_points: list[np.ndarray]) -> list[list[int]]:
    def point(i: int) -> np.ndarray:
        return verts[i] if i < len(verts) else new_points[i - len(verts)]

    p = [point(i) for i in polygon]
    if np.linalg.norm(p[0] - p[2]) <= np.linalg.norm(p[1] - p[3]):
        return [[polygon[0], polygon[1], polygon[2]], [polygon[0], polygon[2], polygon[3]]]
    return [[polygon[0], polygon[1], polygon[3]], [polygon[1], polygon[2], polygon[3]]]


def main_pieces(verts: np.ndarray, faces: np.ndarray, min_fraction: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """Keep the edge-connected pieces with at least `min_fraction` of the largest piece's area."""
    labels = face_components(faces)
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    piece_area = np.bincount(labels, area)
    keep = piece_area[labels] >= min_fraction * piece_area.max()
    v, f, _ = compact(verts, faces[keep])
    return v, f


def tidy_border(verts: np.ndarray, faces: np.ndarray, edge_length: float, min_fraction: float = 0.4,
                iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Even out the border after a cut: collapse edges shorter than `min_fraction` of `edge_length` (where the
    level line passed close to a vertex), then relax each border vertex towards the middle of its two border
    neighbours. Remeshing keeps border vertices fixed, so this is what keeps slivers off the border."""
    verts, faces = collapse_short_edges(verts, faces, min_fraction * edge_length)
    for _ in range(iterations):
        prev, nxt = _border_neighbours(faces, len(verts))
        on = np.flatnonzero(prev >= 0)
        verts[on] = 0.5 * verts[on] + 0.25 * (verts[prev[on]] + verts[nxt[on]])
    return verts, faces


def _border_edges(faces: np.ndarray) -> np.ndarray:
    """[B, 2] directed border edges (each as it runs in its only face)."""
    a = faces.ravel()
    b = np.roll(faces, -1, axis=1).ravel()
    key = np.minimum(a, b) * (int(faces.max()) + 1) + np.maximum(a, b)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    once = counts[inverse] == 1
    return np.stack([a[once], b[once]], axis=1)


def border_loops(faces: np.ndarray) -> int:
    """Number of closed border loops (a pinched border vertex joins its loops into one)."""
    return int(border_loop_labels(faces)[1].max(initial=-1)) + 1


def border_loop_labels(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """([B] the border vertices, [B] the loop each belongs to, 0 ... loops - 1)."""
    edges = _border_edges(faces)
    if len(edges) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    import scipy.sparse as sp  # noqa: PLC0415
    from scipy.sparse.csgraph import connected_components  # noqa: PLC0415

    ids, inverse = np.unique(edges, return_inverse=True)
    inverse = inverse.reshape(-1, 2)
    graph = sp.coo_matrix((np.ones(len(edges)), (inverse[:, 0], inverse[:, 1])), shape=(len(ids), len(ids)))
    return ids, connected_components(graph, directed=False)[1]


def _border_neighbours(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """(previous, next) border vertex of each vertex with exactly one border edge in and one out, else -1."""
    edges = _border_edges(faces)
    prev = np.full(n_vertices, -1, np.int64)
    nxt = np.full(n_vertices, -1, np.int64)
    n_in = np.bincount(edges[:, 1], minlength=n_vertices)
    n_out = np.bincount(edges[:, 0], minlength=n_vertices)
    nxt[edges[:, 0]] = edges[:, 1]
    prev[edges[:, 1]] = edges[:, 0]
    simple = (n_in == 1) & (n_out == 1)
    return np.where(simple, prev, -1), np.where(simple, nxt, -1)


def collapse_short_edges(verts: np.ndarray, faces: np.ndarray, min_length: float) -> tuple[np.ndarray, np.ndarray]:
    """Collapse edges shorter than `min_length` until none is left that can go without breaking the surface.

    A border edge collapses to its midpoint; an edge from a border vertex inwards collapses onto the border
    vertex (the border keeps its place); an inner edge collapses to its midpoint. Edges joining two border
    vertices across the inside stay (collapsing them would pinch the surface), and every collapse must keep
    the surface manifold (the ends share exactly the neighbours opposite the edge: one on the border, two
    inside).
    """
    verts = np.asarray(verts, np.float64).copy()
    faces = np.asarray(faces, np.int64).copy()
    while True:
        faces, collapsed = _collapse_pass(verts, faces, min_length)
        if not collapsed:
            break
    verts, faces, _ = compact(verts, faces)
    return verts, faces


def _collapse_pass(verts: np.ndarray, faces: np.ndarray, min_length: float) -> tuple[np.ndarray, bool]:
    """One pass of collapses; vertices touched in this pass wait for the next."""
    a = np.minimum(faces, np.roll(faces, -1, axis=1)).ravel()
    b = np.maximum(faces, np.roll(faces, -1, axis=1)).ravel()
    edges, counts = np.unique(np.stack([a, b], axis=1), axis=0, return_counts=True)
    length = np.linalg.norm(verts[edges[:, 0]] - verts[edges[:, 1]], axis=1)
    short = np.flatnonzero(length < min_length)
    if len(short) == 0:
        return faces, False
    on_border = np.zeros(len(verts), bool)
    on_border[edges[counts == 1].ravel()] = True
    neighbours: dict[int, set[int]] = {}
    for f in faces:
        for k in range(3):
            neighbours.setdefault(int(f[k]), set()).update((int(f[(k + 1) % 3]), int(f[(k + 2) % 3])))
    touched: set[int] = set()
    remap = np.arange(len(verts))
    for e in short[np.argsort(length[short])]:
        u, v = int(edges[e, 0]), int(edges[e, 1])
        border_edge = counts[e] == 1
        if u in touched or v in touched or len(neighbours[u] & neighbours[v]) != (1 if border_edge else 2):
            continue
        if border_edge or on_border[u] == on_border[v]:
            if not border_edge and on_border[u]:
                continue                                   # a chord between two border vertices
            verts[u] = 0.5 * (verts[u] + verts[v])
        elif on_border[v]:
            u, v = v, u                                    # keep the border vertex u where it is
        remap[v] = u
        touched.update(neighbours[u] | neighbours[v] | {u, v})
    if not touched:
        return faces, False
    faces = remap[faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    return faces[keep], True
