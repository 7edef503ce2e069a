"""Garment-body proximity: closest points on the posed body mesh, signed distances, contact planes.

Queries run every step, so they are numba: a hashed uniform grid over body vertices finds the nearest body
vertex within `reach`; a short walk over the faces around it finds the exact closest point. The sign comes from
the face normal inside a face and the interpolated vertex normal on edges and corners. A contact stores the body
face and barycentric coordinates, so the same body point can be followed to the next frame: the solver's
contact plane for step t -> t+1 is the plane at the point of body(t+1) that was closest at time t, which stays
right when the body moves several centimetres in one frame. Hands can be left out (body.hand_mask), as the paper
does. penetration_stats measures garment sequences with the same queries (bench_sim, simulate).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..geometry.topology import vertex_faces
from . import kernels

_EMPTY = -1
_CELLS_PER_REACH = 1
_OFFSETS = np.array([0, -1, 1])  # own cell first, so the pruning below bites early


@njit(cache=True)
def _cell_key(ix, iy, iz, mask):
    return ((ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)) & mask


@njit(cache=True)
def _build_grid(verts, allowed, cell, table_bits):
    size = 1 << table_bits
    mask = size - 1
    counts = np.zeros(size + 1, np.int64)
    keys = np.full(verts.shape[0], -1, np.int64)
    for i in range(verts.shape[0]):
        if not allowed[i]:
            continue
        k = _cell_key(int(np.floor(verts[i, 0] / cell)), int(np.floor(verts[i, 1] / cell)),
                      int(np.floor(verts[i, 2] / cell)), mask)
        keys[i] = k
        counts[k + 1] += 1
    for k in range(size):
        counts[k + 1] += counts[k]
    fill = counts[:-1].copy()
    items = np.empty(counts[size], np.int64)
    for i in range(verts.shape[0]):
        k = keys[i]
        if k >= 0:
            items[fill[k]] = i
            fill[k] += 1
    return counts, items


@njit(cache=True, inline="always")
def _closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Closest point to p on triangle abc as barycentric (u, v, w) (Ericson, Real-Time Collision Detection).
    Scalar arguments: numba allocates for every small array, and this runs millions of times per second."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - w, w
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return 1.0 - v - w, v, w


@njit(cache=True)
def _query(points, verts, faces, vnormals, vf_off, vf_idx, face_ok, counts, items, cell, table_bits, reach,
           out_face, out_bary, out_dist):
    mask = (1 << table_bits) - 1
    reach2 = reach * reach
    frontier = np.empty(3, np.int64)
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        cx = int(np.floor(px / cell))
        cy = int(np.floor(py / cell))
        cz = int(np.floor(pz / cell))
        best_v = -1
        best_d2 = reach2
        # distance from p to each neighbour cell, to skip those farther than the best vertex so far
        for ox in range(_OFFSETS.size):
            dx = _OFFSETS[ox]
            gx = 0.0 if dx == 0 else (px - (cx + dx + 1) * cell if dx < 0 else (cx + dx) * cell - px)
            for oy in range(_OFFSETS.size):
                dy = _OFFSETS[oy]
                gy = 0.0 if dy == 0 else (py - (cy + dy + 1) * cell if dy < 0 else (cy + dy) * cell - py)
                for oz in range(_OFFSETS.size):
                    dz = _OFFSETS[oz]
                    gz = 0.0 if dz == 0 else (pz - (cz + dz + 1) * cell if dz < 0 else (cz + dz) * cell - pz)
                    if gx * gx + gy * gy + gz * gz >= best_d2:
                        continue
                    k = _cell_key(cx + dx, cy + dy, cz + dz, mask)
                    for s in range(counts[k], counts[k + 1]):
                        v = items[s]
                        ex = verts[v, 0] - px
                        ey = verts[v, 1] - py
                        ez = verts[v, 2] - pz
                        d2 = ex * ex + ey * ey + ez * ez
                        if d2 < best_d2:
                            best_d2 = d2
                            best_v = v
        out_face[i] = _EMPTY
        out_dist[i] = np.inf
        if best_v < 0:
            continue
        # walk: faces around the current best vertices until the closest point stops improving
        best_f = -1
        best_fd2 = np.inf
        bu = 0.0
        bv = 0.0
        bw = 0.0
        frontier[0] = best_v
        n_front = 1
        for _ in range(4):
            improved = False
            for c in range(n_front):
                vtx = frontier[c]
                for s in range(vf_off[vtx], vf_off[vtx + 1]):
                    f = vf_idx[s]
                    if not face_ok[f]:
                        continue
                    ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
                    u, v, w = _closest_on_triangle(px, py, pz, verts[ia, 0], verts[ia, 1], verts[ia, 2],
                                                   verts[ib, 0], verts[ib, 1], verts[ib, 2],
                                                   verts[ic, 0], verts[ic, 1], verts[ic, 2])
                    qx = u * verts[ia, 0] + v * verts[ib, 0] + w * verts[ic, 0] - px
                    qy = u * verts[ia, 1] + v * verts[ib, 1] + w * verts[ic, 1] - py
                    qz = u * verts[ia, 2] + v * verts[ib, 2] + w * verts[ic, 2] - pz
                    d2 = qx * qx + qy * qy + qz * qz
                    if d2 < best_fd2 - 1e-18:
                        best_fd2 = d2
                        best_f = f
                        bu, bv, bw = u, v, w
                        improved = True
            if not improved or best_f < 0 or (bu > 0.0 and bv > 0.0 and bw > 0.0):
                break  # a face-interior closest point next to the nearest vertex is the closest point
            for c in range(3):
                frontier[c] = faces[best_f, c]
            n_front = 3
        if best_f < 0:
            continue
        ia, ib, ic = faces[best_f, 0], faces[best_f, 1], faces[best_f, 2]
        dx_ = px - (bu * verts[ia, 0] + bv * verts[ib, 0] + bw * verts[ic, 0])
        dy_ = py - (bu * verts[ia, 1] + bv * verts[ib, 1] + bw * verts[ic, 1])
        dz_ = pz - (bu * verts[ia, 2] + bv * verts[ib, 2] + bw * verts[ic, 2])
        if bu > 1e-6 and bv > 1e-6 and bw > 1e-6:
            e1x, e1y, e1z = verts[ib, 0] - verts[ia, 0], verts[ib, 1] - verts[ia, 1], verts[ib, 2] - verts[ia, 2]
            e2x, e2y, e2z = verts[ic, 0] - verts[ia, 0], verts[ic, 1] - verts[ia, 1], verts[ic, 2] - verts[ia, 2]
            nx = e1y * e2z - e1z * e2y
            ny = e1z * e2x - e1x * e2z
            nz = e1x * e2y - e1y * e2x
        else:
            nx = bu * vnormals[ia, 0] + bv * vnormals[ib, 0] + bw * vnormals[ic, 0]
            ny = bu * vnormals[ia, 1] + bv * vnormals[ib, 1] + bw * vnormals[ic, 1]
            nz = bu * vnormals[ia, 2] + bv * vnormals[ib, 2] + bw * vnormals[ic, 2]
        dist = np.sqrt(best_fd2)
        out_face[i] = best_f
        out_bary[i, 0] = bu
        out_bary[i, 1] = bv
        out_bary[i, 2] = bw
        out_dist[i] = dist if dx_ * nx + dy_ * ny + dz_ * nz >= 0.0 else -dist


@dataclass
class Proximity:
    """Closest body points of a set of garment vertices (face -1 / distance +inf where none within reach)."""

    face: np.ndarray      # [N] int64
    bary: np.ndarray      # [N,3]
    distance: np.ndarray  # [N] signed: negative inside the body

    @property
    def found(self) -> np.ndarray:
        return self.face >= 0


@njit(cache=True)
def _surface_points(faces, verts, normals, face, bary, point, normal):
    for i in range(face.shape[0]):
        f = face[i]
        if f < 0:
            for r in range(3):
                point[i, r] = 0.0
                normal[i, r] = 0.0
            continue
        ln = 0.0
        for r in range(3):
            pr = 0.0
            nr = 0.0
            for k in range(3):
                pr += bary[i, k] * verts[faces[f, k], r]
                nr += bary[i, k] * normals[faces[f, k], r]
            point[i, r] = pr
            normal[i, r] = nr
            ln += nr * nr
        ln = np.sqrt(ln) + 1e-30
        for r in range(3):
            normal[i, r] /= ln


@dataclass
class BodyPose:
    """Body vertex positions of one frame with their unit normals (computed once, used by every query)."""

    verts: np.ndarray
    normals: np.ndarray


class BodyCollider:
    """A body mesh topology (fixed) whose vertex positions change per frame; hands or other parts can be
    excluded from collision with `exclude` (vertex mask)."""

    def __init__(self, faces: np.ndarray, n_vertices: int, exclude: np.ndarray | None = None) -> None:
        self.faces = np.ascontiguousarray(faces, np.int64)
        self.n_vertices = int(n_vertices)
        self.vf_offsets, self.vf_faces = vertex_faces(self.faces, self.n_vertices)
        excl = np.zeros(self.n_vertices, bool) if exclude is None else np.asarray(exclude, bool)
        self.face_ok = ~excl[self.faces].any(1)
        self.vert_ok = np.zeros(self.n_vertices, bool)
        self.vert_ok[self.faces[self.face_ok].ravel()] = True
        self._table_bits = max(10, int(np.ceil(np.log2(2 * self.n_vertices))))

    def pose(self, verts: np.ndarray) -> BodyPose:
        verts = np.ascontiguousarray(verts, np.float64)
        return BodyPose(verts, kernels.vertex_normals(verts, self.faces))

    def query(self, points: np.ndarray, pose: BodyPose | np.ndarray, reach: float = 0.05) -> Proximity:
        """Closest body points to `points` [N,3] on the posed body, searched within `reach` (m)."""
        pose = pose if isinstance(pose, BodyPose) else self.pose(pose)
        points = np.ascontiguousarray(points, np.float64)
        cell = reach / _CELLS_PER_REACH
        counts, items = _build_grid(pose.verts, self.vert_ok, cell, self._table_bits)
        face = np.empty(len(points), np.int64)
        bary = np.zeros((len(points), 3))
        dist = np.empty(len(points))
        _query(points, pose.verts, self.faces, pose.normals, self.vf_offsets, self.vf_faces, self.face_ok,
               counts, items, cell, self._table_bits, reach, face, bary, dist)
        return Proximity(face, bary, dist)

    def surface_point(self, prox: Proximity, pose: BodyPose | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and unit interpolated normals [N,3] of the contacts' body points on the posed body
        (rows without a contact are zero)."""
        pose = pose if isinstance(pose, BodyPose) else self.pose(pose)
        point = np.empty((len(prox.face), 3))
        normal = np.empty((len(prox.face), 3))
        _surface_points(self.faces, pose.verts, pose.normals, prox.face, prox.bary, point, normal)
        return point, normal


def penetration_stats(garment_frames: np.ndarray, body_frames: np.ndarray, collider: BodyCollider,
                      depth: float = 2e-3, reach: float = 0.15) -> dict[str, float]:
    """Body penetration of a garment sequence [T,V,3] against body frames [T,Vb,3]: the largest per-frame
    fraction of vertices deeper than `depth` inside the body, the mean fraction, and the deepest point (m)."""
    fractions, deepest = [], 0.0
    for g, b in zip(garment_frames, body_frames):
        d = collider.query(g, b, reach=reach).distance
        fractions.append(float(np.mean(d < -depth)))
        deepest = max(deepest, float(-d.min()) if np.isfinite(d).any() else 0.0)
    return {"max_fraction_deeper": max(fractions), "mean_fraction_deeper": float(np.mean(fractions)),
            "max_depth_m": max(deepest, 0.0), "depth_threshold_m": depth}
