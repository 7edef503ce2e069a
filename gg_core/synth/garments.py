"""Procedural tailoring of garment templates around the body in its rest (A-) pose. Numpy + scipy + xatlas.

Every garment is built from tubes of rings: each ring follows the body's cross-section envelope at its
height (the largest body radius per angle, arms left out) plus a clearance, so the garment starts outside
the body. The T-shirt bridges two sleeve tubes (rings around the upper arms) into holes cut in its torso
tube. A final relaxation smooths the surface and pushes every vertex back out to the clearance.
UVs come from an xatlas atlas; `uv_scale` converts UV units to metres so shader patterns have a real size.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..body.model import BodyModel
from ..errors import InputError
from .proximity import MeshProximity

CLEARANCE = 0.012          # m between body and garment at rest
ARM_ROOTS = ("left_shoulder", "right_shoulder")


@dataclass
class Garment:
    name: str
    fabric: str
    vertices: np.ndarray            # [N,3] float64, rest pose, gg coordinates
    faces: np.ndarray               # [F,3] int64
    uvs: np.ndarray                 # [U,2] in [0,1]
    face_uvs: np.ndarray            # [F,3] indices into uvs
    uv_scale: float                 # metres per UV unit
    regions: dict[str, np.ndarray] = field(default_factory=dict)  # name -> per-vertex weight in [0,1]

    @property
    def area(self) -> float:
        tri = self.vertices[self.faces]
        return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())


class _Body:
    """The rest body with the measurements tailoring needs."""

    def __init__(self, body: BodyModel) -> None:
        self.model = body
        self.vertices = body.rest_vertices.astype(np.float64)
        self.faces = np.asarray(body.faces, np.int64)
        self.proximity = MeshProximity(self.vertices, self.faces)
        arm_joints = set()
        for root in ARM_ROOTS:
            arm_joints |= _subtree(body.parents, body.joint(root))
        self.arm = body.weights[:, sorted(arm_joints)].sum(axis=1) > 0.5
        self.trunk = self.vertices[~self.arm]

    def joint(self, name: str) -> np.ndarray:
        return self.model.rest_joints[self.model.joint(name)].astype(np.float64)

    def envelope(self, y: float, thetas: np.ndarray, center: np.ndarray, slab: float = 0.03) -> np.ndarray:
        """Largest trunk radius around the vertical axis through `center` (x, z) per angle, at height y."""
        pts = self.trunk[np.abs(self.trunk[:, 1] - y) < slab]
        return _polar_envelope(pts[:, 0] - center[0], pts[:, 2] - center[1], thetas)


def _subtree(parents: np.ndarray, root: int) -> set[int]:
    out = {root}
    for j in range(root + 1, len(parents)):
        if parents[j] in out:
            out.add(j)
    return out


def _polar_envelope(dx: np.ndarray, dz: np.ndarray, thetas: np.ndarray) -> np.ndarray:
    """Max radius of points per angular bin (angle 0 = +Z front, 90 deg = +X), empty bins interpolated."""
    n = len(thetas)
    ang = np.arctan2(dx, dz) % (2 * np.pi)
    r = np.hypot(dx, dz)
    bins = np.floor((ang - thetas[0]) / (2 * np.pi) * n + 0.5).astype(int) % n
    env = np.full(n, np.nan)
    np.fmax.at(env, bins, r)
    known = np.flatnonzero(~np.isnan(env))
    if len(known) == 0:
        raise ValueError("no body points at this height")
    idx = np.arange(n)
    env = np.interp(idx, np.r_[known - n, known, known + n], np.tile(env[known], 3))
    # widen by one bin on each side, then smooth: the ring must clear points between its vertices too
    env = np.maximum.reduce([env, np.roll(env, 1), np.roll(env, -1)])
    return np.convolve(np.r_[env[-2:], env, env[:2]], np.ones(5) / 5, mode="valid")


def _tube_faces(rows: int, cols: int, start: int = 0) -> np.ndarray:
    """Triangles of `rows` closed rings of `cols` vertices stored ring after ring from `start`."""
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols), indexing="ij")
    a = start + i * cols + j
    b = start + i * cols + (j + 1) % cols
    c, d = a + cols, b + cols
    return np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])


def _bridge(loop_a: np.ndarray, loop_b: np.ndarray, verts: np.ndarray) -> np.ndarray:
    """Triangulate the band between two closed vertex loops running the same way (shortest diagonal first)."""
    shift = int(np.argmin(np.linalg.norm(verts[loop_b] - verts[loop_a[0]], axis=1)))
    loop_b = np.roll(loop_b, -shift)
    na, nb = len(loop_a), len(loop_b)
    i = j = 0
    faces = []
    while i < na or j < nb:
        a0, a1 = loop_a[i % na], loop_a[(i + 1) % na]
        b0, b1 = loop_b[j % nb], loop_b[(j + 1) % nb]
        shorter = np.linalg.norm(verts[a1] - verts[b0]) <= np.linalg.norm(verts[b1] - verts[a0])
        advance_a = j >= nb or (i < na and shorter)
        if advance_a:
            faces.append([a0, b0, a1])
            i += 1
        else:
            faces.append([a0, b0, b1])
            j += 1
    return np.asarray(faces, np.int64)


def _neighbours(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique edges [E,2] and vertex degrees [n] of a triangle mesh."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    return e, np.bincount(e.ravel(), minlength=n)


def _relax(verts: np.ndarray, faces: np.ndarray, body: _Body, fixed: np.ndarray, iterations: int = 12,
           clearance: float = CLEARANCE) -> np.ndarray:
    """Laplacian smoothing alternated with pushing vertices out of the body to `clearance`."""
    edges, degree = _neighbours(faces, len(verts))
    verts = verts.copy()
    for it in range(iterations + 1):
        if it:
            acc = np.zeros_like(verts)
            np.add.at(acc, edges[:, 0], verts[edges[:, 1]])
            np.add.at(acc, edges[:, 1], verts[edges[:, 0]])
            mean = acc / np.maximum(degree, 1)[:, None]
            move = ~fixed
            verts[move] += 0.5 * (mean[move] - verts[move])
        verts = push_out(verts, body.proximity, clearance)
        verts = _lift_edges(verts, edges, body.proximity, clearance)
    return verts


def _lift_edges(verts: np.ndarray, edges: np.ndarray, proximity: MeshProximity, clearance: float) -> np.ndarray:
    """Long edges over convex body parts (shoulders) can cut in although both ends are outside:
    lift both ends of every edge whose midpoint is closer than half the clearance."""
    mid = 0.5 * (verts[edges[:, 0]] + verts[edges[:, 1]])
    foot, _, face = proximity.closest(mid)
    normal = proximity.face_normals[face]
    height = np.einsum("nc,nc->n", mid - foot, normal)
    low = height < 0.5 * clearance
    if not low.any():
        return verts
    lift = np.zeros_like(verts)
    push = normal[low] * (clearance - height[low])[:, None]
    for k in (0, 1):
        np.maximum.at(lift, edges[low, k], np.where(push > 0, push, 0))
        np.minimum.at(lift, edges[low, k], np.where(push < 0, push, 0))
    return verts + lift


def push_out(verts: np.ndarray, proximity: MeshProximity, clearance: float) -> np.ndarray:
    """Move vertices closer than `clearance` to the body (or inside it) out along the surface normal."""
    foot, _, face = proximity.closest(verts)
    normal = proximity.face_normals[face]
    height = np.einsum("nc,nc->n", verts - foot, normal)
    close = height < clearance
    out = verts.copy()
    out[close] = foot[close] + normal[close] * clearance
    return out


def _rings(body: _Body, heights: np.ndarray, n_theta: int, center: np.ndarray, ease: Callable[[float], float],
           a_line: bool) -> np.ndarray:
    """Rings [rows, n_theta, 3] at `heights` (top first): body envelope (+ A-line from above) + ease(y)."""
    thetas = np.arange(n_theta) * 2 * np.pi / n_theta
    rings, running = [], np.zeros(n_theta)
    for y in heights:
        env = body.envelope(y, thetas, center)
        running = np.maximum(running, env) if a_line else env
        r = running + CLEARANCE + ease(y)
        rings.append(np.stack([center[0] + r * np.sin(thetas), np.full(n_theta, y), center[1] + r * np.cos(thetas)], 1))
    return np.stack(rings)


def _resolution(length: float, circumference: float, target: int) -> tuple[int, int]:
    """Rows and ring size for a tube of this size with about `target` vertices and square-ish cells."""
    h = math.sqrt(length * circumference / target)
    return max(int(round(length / h)) + 1, 4), max(int(round(circumference / h)), 12)


def _skirt_like(body: _Body, name: str, top: float, hem: float, flare: float, target: int, fabric: str) -> Garment:
    pelvis = body.joint("pelvis")
    center = np.array([pelvis[0], pelvis[2]])
    thetas = np.arange(64) * 2 * np.pi / 64
    circ = 2 * np.pi * (body.envelope(0.5 * (top + hem), thetas, center).mean() + CLEARANCE + flare * (top - hem) / 2)
    rows, cols = _resolution(top - hem, circ, target)
    heights = np.linspace(top, hem, rows)
    verts = _rings(body, heights, cols, center, lambda y: flare * (top - y), a_line=True).reshape(-1, 3)
    faces = _tube_faces(rows, cols)
    pin = np.zeros(len(verts), bool)
    pin[:cols] = True
    verts = _relax(verts, faces, body, fixed=pin, iterations=4)
    return _finish(name, fabric, verts, faces, body, {"pin": pin.astype(float)}, torso_top=top, hem=hem)


def skirt(body: BodyModel, target: int) -> Garment:
    """A-line skirt from the natural waist to just above the knees; the waistband is pinned."""
    b = _Body(body)
    return _skirt_like(b, "skirt", top=b.joint("spine1")[1] + 0.03, hem=b.joint("left_knee")[1] + 0.08,
                       flare=0.25, target=target, fabric="cotton")


def dress(body: BodyModel, target: int) -> Garment:
    """Long strapless tube dress from under the arms to mid-calf; the top band is pinned."""
    b = _Body(body)
    return _skirt_like(b, "dress", top=b.joint("spine3")[1] - 0.08, hem=b.joint("left_knee")[1] - 0.15,
                       flare=0.18, target=target, fabric="silk")


def tshirt(body: BodyModel, target: int) -> Garment:
    """T-shirt with short sleeves: torso tube (hem to neck) with arm holes bridged to two sleeve tubes."""
    b = _Body(body)
    spine = b.joint("spine2")
    center = np.array([0.0, spine[2]])
    hem = b.joint("pelvis")[1] - 0.02
    neck = b.joint("neck")
    shoulder_y = b.joint("left_shoulder")[1]
    armpit = b.joint("spine3")[1] - 0.04
    thetas = np.arange(64) * 2 * np.pi / 64
    circ = 2 * np.pi * (b.envelope(armpit - 0.1, thetas, center).mean() + CLEARANCE + 0.02)
    sleeve_share = 0.25                      # of the vertices
    rows, cols = _resolution(shoulder_y - hem + 0.12, circ, int(target * (1 - sleeve_share)))
    cols += cols % 4                          # symmetric hole columns around both sides
    # torso rings up to the shoulder line, then a yoke of rings closing in on the neck
    n_yoke = max(3, rows // 5)
    torso_heights = np.linspace(hem, shoulder_y, rows - n_yoke)
    torso = _rings(b, torso_heights[::-1], cols, center, lambda y: 0.02, a_line=False)[::-1]
    th = np.arange(cols) * 2 * np.pi / cols
    neck_r = b.envelope(neck[1] - 0.01, th, np.array([neck[0], neck[2]])) + 0.025
    neck_ring = np.stack([neck[0] + neck_r * np.sin(th), np.full(cols, neck[1] - 0.01),
                          neck[2] + neck_r * np.cos(th)], 1)
    s = np.linspace(0, 1, n_yoke + 1)[1:, None, None]
    yoke = (1 - s) * torso[-1][None] + s * neck_ring[None]
    grid = np.concatenate([torso, yoke])                    # [rows, cols, 3], hem first
    n_rows = len(grid)
    verts = grid.reshape(-1, 3)
    faces = _tube_faces(n_rows, cols)
    # arm holes: rectangles of grid cells around theta = +-90 deg from the armpit row into the yoke
    row_lo = int(np.searchsorted(torso_heights, armpit))
    row_hi = len(torso) + 1
    half = max(int(round(cols * 0.045)), 2)      # about +-16 deg: the arm's thickness at the torso side
    keep = np.ones(len(faces), bool)
    cell = np.arange(len(faces)) % ((n_rows - 1) * cols)
    cell_row, cell_col = cell // cols, cell % cols
    sleeve_faces = []
    for side, col_center in (("left", cols // 4), ("right", 3 * cols // 4)):
        offset = (cell_col - col_center + cols // 2) % cols - cols // 2
        keep &= ~((cell_row >= row_lo) & (cell_row < row_hi) & (offset >= -half) & (offset < half))
        loop = _rect_loop(row_lo, row_hi, col_center - half, col_center + half, cols)
        # sleeve rings around the upper arm, from near the shoulder towards the elbow
        root, elbow = b.joint(f"{side}_shoulder"), b.joint(f"{side}_elbow")
        axis = (elbow - root) / np.linalg.norm(elbow - root)
        sleeve_rows = max(3, int(round(0.16 / (circ / cols))))
        rings = _arm_rings(b, root, axis, np.linspace(0.06, 0.22, sleeve_rows), len(loop), side, verts[loop])
        first = len(verts)
        verts = np.concatenate([verts, rings.reshape(-1, 3)])
        sleeve_faces.append(_tube_faces(sleeve_rows, len(loop), start=first))
        sleeve_faces.append(_bridge(loop, np.arange(first, first + len(loop)), verts))
    faces = np.concatenate([faces[keep], *sleeve_faces])
    verts, faces = _drop_unused(verts, faces)      # the grid vertices inside the arm holes
    verts = _relax(verts, faces, b, fixed=np.zeros(len(verts), bool), iterations=15, clearance=CLEARANCE)
    return _finish("tshirt", "jersey", verts, faces, b, {}, torso_top=armpit, hem=hem)


def _rect_loop(r0: int, r1: int, c0: int, c1: int, cols: int) -> np.ndarray:
    """Vertex indices around a hole of grid cells rows [r0, r1) x cols [c0, c1) (ring-major grid)."""
    idx = lambda r, c: r * cols + c % cols  # noqa: E731
    path = [idx(r0, c) for c in range(c0, c1)]                 # bottom edge
    path += [idx(r, c1) for r in range(r0, r1)]                # one side up
    path += [idx(r1, c) for c in range(c1, c0, -1)]            # top edge back
    path += [idx(r, c0) for r in range(r1, r0, -1)]            # other side down
    return np.asarray(path, np.int64)


def _arm_rings(body: _Body, root: np.ndarray, axis: np.ndarray, ss: np.ndarray, n: int, side: str,
               hole: np.ndarray) -> np.ndarray:
    """Rings [len(ss), n, 3] around the arm axis, angularly aligned with the hole loop they bridge to."""
    up = np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, up) if abs(axis @ up) < 0.95 else np.array([0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    arm = body.vertices[body.arm & ((body.vertices[:, 0] > 0) == (side == "left"))]   # left arm at +x
    rel_hole = hole - hole.mean(axis=0)
    start = math.atan2(rel_hole[0] @ e2, rel_hole[0] @ e1)
    # winding of the hole loop seen along the arm axis, so the sleeve rings run the same way round
    direction = np.sign(np.cross(rel_hole, np.roll(rel_hole, -1, axis=0)).sum(axis=0) @ axis) or 1.0
    thetas = start + direction * np.arange(n) * 2 * np.pi / n
    rings = []
    for s in ss:
        c = root + axis * s
        rel = arm - c
        along = rel @ axis
        near = rel[np.abs(along) < 0.03]
        # envelope on a regular grid of angles from e1 towards e2, then read at the ring's own angles
        grid = np.arange(64) * 2 * np.pi / 64
        env = np.interp(thetas % (2 * np.pi), grid, _polar_envelope(near @ e2, near @ e1, grid), period=2 * np.pi)
        r = env + CLEARANCE + 0.025
        rings.append(c + r[:, None] * (np.cos(thetas)[:, None] * e1 + np.sin(thetas)[:, None] * e2))
    return np.stack(rings)


def _drop_unused(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.zeros(len(verts), bool)
    used[faces] = True
    remap = np.cumsum(used) - 1
    return verts[used], remap[faces]


def _orient_outward(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Flip the winding so normals point away from the vertical body axis on average."""
    tri = verts[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out = tri.mean(1) * np.array([1.0, 0.0, 1.0])
    return faces if np.einsum("nc,nc->", n, out) >= 0 else faces[:, ::-1].copy()


def _finish(name: str, fabric: str, verts: np.ndarray, faces: np.ndarray, body: _Body,
            regions: dict[str, np.ndarray], torso_top: float, hem: float) -> Garment:
    """Common regions (hem band, side seam, front patch), outward winding, and the UV atlas."""
    import xatlas  # noqa: PLC0415

    faces = _orient_outward(verts, faces)
    y = verts[:, 1]
    regions = dict(regions)
    regions["hem"] = (y < hem + 0.06).astype(float)
    angle = np.degrees(np.arctan2(verts[:, 0], verts[:, 2] - verts[:, 2].mean()))
    regions["side_seam"] = ((np.abs(angle - 90) < 10) & (y < torso_top)).astype(float)
    mid = 0.5 * (torso_top + hem)
    front = verts[np.argmax(np.where(np.abs(y - mid) < 0.05, verts[:, 2], -np.inf))]
    d = np.linalg.norm(verts - front, axis=1)
    regions["patch"] = np.clip((0.11 - d) / 0.03, 0.0, 1.0)
    vmap, face_uvs, uvs = xatlas.parametrize(verts.astype(np.float32), faces.astype(np.uint32))
    tri3 = verts[vmap][face_uvs]
    tri2 = uvs[face_uvs]
    area3 = 0.5 * np.linalg.norm(np.cross(tri3[:, 1] - tri3[:, 0], tri3[:, 2] - tri3[:, 0]), axis=1).sum()
    e1, e2 = tri2[:, 1] - tri2[:, 0], tri2[:, 2] - tri2[:, 0]
    area2 = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    # xatlas splits vertices along chart seams: its corners map back to ours through vmap
    faces = vmap[face_uvs].astype(np.int64)
    return Garment(name, fabric, verts, faces, uvs.astype(np.float64), face_uvs.astype(np.int64),
                   float(math.sqrt(area3 / area2)), regions)


GARMENTS: dict[str, Callable[[BodyModel, int], Garment]] = {"skirt": skirt, "dress": dress, "tshirt": tshirt}


def tailor(body: BodyModel, name: str, target_vertices: int) -> Garment:
    if name not in GARMENTS:
        raise InputError(f"unknown garment '{name}'", "--garment", f"choose one of: {', '.join(GARMENTS)}")
    return GARMENTS[name](body, target_vertices)
