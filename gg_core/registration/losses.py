"""Geometric terms of the registration loss (REFERENCE §3), all torch and differentiable in the vertices x [V, 3].

- L_bend   = mean_h |e_h|^2 / (A_a + A_b) (theta_h - theta_rest_h)^2: dihedral angle theta between the two face
             normals of every interior edge, weighted by the template's edge length and face areas; the mean
             over hinges (not the sum) keeps its weight independent of the mesh resolution. The rest angles are
             settable (set_rest): bending towards flat instead was measured to pull a garment whose template
             has folds away from its true shape (tiny capture, frame 0 started at ground truth: Chamfer
             0.26 cm after 100 iterations vs 0.10 cm without bending).
- L_strain = sum_f V_f (lam/2 tr(G)^2 + mu tr(G^2)), G = (F^T F - I)/2 against each face's 2D rest shape
             given by rest edge lengths, V = thickness x rest area, HOOD's default fabric (physics.cloth:
             quadratic form in the squared edge lengths).
- L_body   = sum_i max(eps - (x_i - c_i) . n_i, 0)^3 with (c_i, n_i) the closest point and normal of the body
             (hands excluded), eps = 3 mm; contacts are found outside autograd and refreshed by the caller.
- L_VE     = sum_k max(L_k - l_k, 0)^2 over virtual edges: from each template vertex a ray along -n that hits a
             facing face (normals' dot < -0.7) links the vertex to the hit point; only compression costs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..geometry.raycast import RayCaster
from ..geometry.topology import build_topology, face_areas
from ..physics.cloth import Cloth
from ..physics.contact import BodyCollider, BodyPose
from ..physics.energies import dihedral_angles, face_q, vertex_normals

BODY_EPS = 3e-3          # m
FACING_COS = -0.7


class Bending:
    """L_bend of a fixed topology: weights from the template, rest dihedral angles settable (set_rest)."""

    def __init__(self, template: np.ndarray, faces: np.ndarray) -> None:
        self.topology = topo = build_topology(faces, len(template))
        self.hinges = torch.from_numpy(topo.hinges)
        template = np.asarray(template, np.float64)
        e = topo.edges[topo.hinge_edges]
        length_sq = ((template[e[:, 0]] - template[e[:, 1]]) ** 2).sum(1)
        area = face_areas(template, topo.faces)[topo.hinge_faces].sum(1)
        self.weight = torch.from_numpy(length_sq / np.maximum(area, 1e-20))
        self.rest_angle = self.angles(template)

    def angles(self, positions: np.ndarray) -> torch.Tensor:
        """[H] dihedral angles of a mesh with this topology."""
        return dihedral_angles(torch.from_numpy(np.asarray(positions, np.float64)), self.hinges)

    def set_rest(self, rest_angle: torch.Tensor) -> None:
        self.rest_angle = rest_angle

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        d = dihedral_angles(x, self.hinges) - self.rest_angle.to(x.dtype)
        d = torch.atan2(torch.sin(d), torch.cos(d))     # wrap: a hinge near +-pi must not see a 2 pi jump
        return (self.weight.to(x.dtype) * d * d).mean()


class Strain:
    """L_strain against rest edge lengths that may change per frame (set_rest), in float64 for small strains."""

    def __init__(self, template: np.ndarray, faces: np.ndarray) -> None:
        self.cloth = Cloth(template, faces)
        self.edges = self.cloth.topology.edges
        self.set_rest(self.lengths(template))

    def lengths(self, positions: np.ndarray) -> np.ndarray:
        """[E] edge lengths of a mesh with this topology."""
        return np.linalg.norm(positions[self.edges[:, 0]] - positions[self.edges[:, 1]], axis=1)

    def set_rest(self, rest_lengths: np.ndarray) -> None:
        """Rest shape = the 2D triangles with these edge lengths."""
        self.cloth.rest_lengths = torch.from_numpy(np.asarray(rest_lengths, np.float64))
        with torch.no_grad():
            rest = self.cloth.rest()
        self.faces, self.rest_sq, self.c = rest.faces, rest.face_rest_sq, rest.stretch_c

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        q = face_q(x.double(), self.faces, self.rest_sq)
        return torch.einsum("fk,fkl,fl->", q, self.c, q).to(x.dtype)


@dataclass
class Contacts:
    """Closest body points and unit normals per garment vertex ([V, 3]; inactive rows have no body in reach)."""

    points: torch.Tensor
    normals: torch.Tensor
    active: torch.Tensor   # [V] float 0/1


class BodyTerm:
    """L_body against one body frame; `contacts(x)` queries the closest body points (numba, no gradient)."""

    def __init__(self, collider: BodyCollider, body_verts: np.ndarray, eps: float = BODY_EPS,
                 reach: float = 0.05) -> None:
        self.collider, self.eps, self.reach = collider, eps, reach
        self.pose: BodyPose = collider.pose(body_verts)

    def contacts(self, x: torch.Tensor) -> Contacts:
        prox = self.collider.query(x.detach().double().numpy(), self.pose, reach=self.reach)
        points, normals = self.collider.surface_point(prox, self.pose)
        dtype = x.dtype
        return Contacts(torch.from_numpy(points).to(dtype), torch.from_numpy(normals).to(dtype),
                        torch.from_numpy(prox.found.astype(np.float64)).to(dtype))

    def __call__(self, x: torch.Tensor, contacts: Contacts) -> torch.Tensor:
        return body_loss(x, contacts, self.eps)


def body_loss(x: torch.Tensor, contacts: Contacts, eps: float = BODY_EPS) -> torch.Tensor:
    gap = eps - ((x - contacts.points) * contacts.normals).sum(-1)
    return (torch.clamp(gap, min=0.0) ** 3 * contacts.active).sum()


@dataclass
class VirtualEdges:
    """Edges from a vertex to a point (face + barycentrics) on the facing side of the garment."""

    vertex: torch.Tensor   # [K] long
    corners: torch.Tensor  # [K, 3] long: vertices of the hit face
    bary: torch.Tensor     # [K, 3]
    rest: torch.Tensor     # [K] template lengths

    def __len__(self) -> int:
        return len(self.vertex)

    def lengths(self, x: torch.Tensor) -> torch.Tensor:
        far = (self.bary.to(x.dtype)[:, :, None] * x[self.corners]).sum(1)
        return (x[self.vertex] - far).norm(dim=-1)

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        if len(self) == 0:
            return x.sum() * 0.0
        return (torch.clamp(self.rest.to(x.dtype) - self.lengths(x), min=0.0) ** 2).sum()


def virtual_edges(template: np.ndarray, faces: np.ndarray, facing_cos: float = FACING_COS) -> VirtualEdges:
    """Virtual edges of the template: from every vertex along -n to the first hit face whose normal faces it."""
    verts = np.asarray(template, np.float64)
    faces = np.asarray(faces, np.int64)
    normals = vertex_normals(verts, faces)
    tri = verts[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)
    caster = RayCaster([(verts, faces)])
    scale = float(np.linalg.norm(verts.max(0) - verts.min(0)))
    origins = verts - 1e-6 * scale * normals     # start just behind the own surface: skip the own faces
    hit_face, ray, locations = caster.intersector.intersects_id(origins, -normals, multiple_hits=False,
                                                                return_locations=True)
    facing = (fn[hit_face] * normals[ray]).sum(1) < facing_cos
    own = (faces[hit_face] == ray[:, None]).any(1)
    keep = facing & ~own
    hit_face, ray, locations = hit_face[keep], ray[keep], locations[keep]
    bary = _barycentric(tri[hit_face], locations)
    rest = np.linalg.norm(verts[ray] - locations, axis=1)
    return VirtualEdges(torch.from_numpy(ray.astype(np.int64)), torch.from_numpy(faces[hit_face]),
                        torch.from_numpy(bary), torch.from_numpy(rest))


def _barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """[N, 3] barycentric coordinates of points p in triangles tri [N, 3, 3] (p in the triangle's plane)."""
    e1, e2, d = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], p - tri[:, 0]
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    d1, d2 = (d * e1).sum(1), (d * e2).sum(1)
    den = np.maximum(d11 * d22 - d12 * d12, 1e-30)
    b1 = (d22 * d1 - d12 * d2) / den
    b2 = (d11 * d2 - d12 * d1) / den
    return np.stack((1 - b1 - b2, b1, b2), 1)
