"""The bevel a visual hull puts on a garment's free border (a hem), and its removal.

Why: silhouettes cannot see under a hem. The hull closes beneath a skirt with a surface that turns from the cloth
inwards towards the legs, and a camera that sees that surface from above at a slant sees the cloth's edge just
behind it, so the garment vote keeps a band of it. The cut then leaves a lip that curls under the garment: on the
demo capture's template (walk frame 0) the hem's last two rings face down (mean normal y -0.70 and -0.62, three rings
in -0.03) and lie 2.2 cm inside the rings above, 11 and 7 mm off the true cloth, which hangs straight to its edge
(normal y -0.06 on its last ring). Registration keeps the template's shape at rest, so every frame carries the lip.
A border that rests on the body (a waistband) has no such lip: the hull follows the body past it.

What tells the lip: not how sharply the surface turns (within the hem's last ring, the angle between a vertex's
normal and the normals two rings in does not rank the vertices' distance to the truth: Spearman 0.02), but which
border hangs free: the demo's hem lies a median 59 mm from the body (5th percentile 13 mm), its waist at most 16 mm.
How much is cut, measured (2026-11-26, session 15), in edge lengths of the template (about 1 cm on the demo):
- the registered demo meshes of session 14 with the faces on the hem's last ring removed, offline (every third
  frame), CD / p2m (cm) / F@1cm: walk 0.327 / 0.301 / 95.77 -> 0.326 / 0.289 / 95.84 %, arm swing 0.366 / 0.337 /
  94.17 -> 0.363 / 0.323 / 94.27 %, torso twist 0.349 / 0.318 / 94.99 -> 0.350 / 0.310 / 94.96 %; two rings:
  p2m 0.285 / 0.317 / 0.305 cm but CD 0.339 / 0.373 / 0.361 cm and F@1cm 95.07 / 93.68 / 94.29 %;
- the template alone (walk frame 0 of the captures of seeds 0, 3, 5), width 0 -> 1: CD 0.419 -> 0.421, 0.422 ->
  0.423, 0.403 -> 0.403 cm; p2m 0.355 -> 0.344, 0.364 -> 0.357, 0.338 -> 0.330 cm; F@1cm 91.47 -> 91.35, 91.47 ->
  91.41, 92.40 -> 92.59 %; on seed 0 width 0.5: 0.418 / 0.348 cm / 91.50 %, width 1.5: 0.425 / 0.340 cm / 91.19 %;
- stages 1 and 2 on the demo capture (3 x 30 frames), width 0 (session 14) -> 1: CD 0.345 -> 0.340 cm, p2m 0.318
  -> 0.305 cm, F@1cm 95.07 -> 95.33 % (walk 0.325 / 0.299 / 95.85 -> 0.324 / 0.290 / 95.98 %, arm swing 0.364 /
  0.337 / 94.24 -> 0.356 / 0.319 / 94.65 %, torso twist 0.347 / 0.317 / 95.10 -> 0.340 / 0.304 / 95.37 %); on arm
  swing (frames 3, 10, 17, 24) the hem's last two rings went from 6.9 to 4.5 mm off the truth on average, the
  interior stayed at 3.1 mm.
On the tiny preset (2.3 cm pixels, the hull's voxel clamped to 1 cm) the lip is not what limits the template: one
edge length costs CD 1.496 -> 1.539 cm (p2m 1.509 -> 1.504 cm, F@1cm 48.4 -> 48.1 %), half an edge 1.509 / 1.504 cm /
48.5 %. The width stays in edge lengths, as measured end to end on the demo.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from ..geometry.topology import build_topology
from ..metrics.surface import point_to_mesh
from .mesh_graph import vertex_area
from .surface_cut import border_loop_labels, cut_at_level, main_pieces

FREE_CLEARANCE = 0.03     # m: a border loop whose median distance to the body is larger hangs free


def free_border(verts: np.ndarray, faces: np.ndarray, bodies: Sequence[tuple[np.ndarray, np.ndarray]],
                clearance: float = FREE_CLEARANCE) -> np.ndarray:
    """[V] bool: the vertices of the border loops whose median distance to the nearest of the `bodies` (verts,
    faces) exceeds `clearance`."""
    ids, loop = border_loop_labels(faces)
    out = np.zeros(len(verts), bool)
    if len(ids) == 0:
        return out
    distance = np.min([point_to_mesh(verts[ids], *body) for body in bodies], axis=0)
    for k in range(loop.max() + 1):
        members = loop == k
        if np.median(distance[members]) > clearance:
            out[ids[members]] = True
    return out


def trim_free_border(verts: np.ndarray, faces: np.ndarray, bodies: Sequence[tuple[np.ndarray, np.ndarray]],
                     width: float, piece_fraction: float = 0.2) -> tuple[np.ndarray, np.ndarray, dict]:
    """(verts, faces, log): the band within `width` (m, along the surface's edges) of the free border loops
    (free_border) cut off along the level line of that distance."""
    free = free_border(verts, faces, bodies)
    log = {"width_m": width, "free_border_vertices": int(free.sum())}
    if width <= 0 or not free.any():
        return verts, faces, log
    a, b = build_topology(faces, len(verts)).edges.T
    length = np.linalg.norm(verts[a] - verts[b], axis=1)
    graph = sp.coo_matrix((length, (a, b)), shape=(len(verts), len(verts))).tocsr()
    distance = dijkstra(graph, directed=False, indices=np.flatnonzero(free), min_only=True, limit=3.0 * width)
    area = vertex_area(verts, faces).sum()
    out_v, out_f = main_pieces(*cut_at_level(verts, faces, np.minimum(distance, 3.0 * width), width),
                               piece_fraction)
    log["area_removed_share"] = float(1.0 - vertex_area(out_v, out_f).sum() / area)
    return out_v, out_f, log
