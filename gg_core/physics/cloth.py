"""A garment as the simulator sees it: template mesh, rest state, per-vertex material, pins.

Rest shape. Each face's 2D rest shape follows from its three rest edge lengths (law of cosines), so the
per-edge rest lengths are the one rest-shape parameter the fitting optimizes (as in the paper). Because the
Green strain of a triangle is linear in its squared edge lengths, StVK becomes a quadratic form in
q_k = l_k^2 - L_k^2:  psi = q^T C q with C = V (mu tr(B_k B_l) + lam/2 tr B_k tr B_l), where
B_k = 1/2 Dm^-T dG/dq_k Dm^-1. The same C serves the torch energy and the numba solver.

`Cloth` holds torch tensors (differentiable); `Cloth.rest()` derives the rest quantities (differentiable in
rest lengths and material) and `Cloth.numeric()` freezes them into numpy arrays for the fast solver.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import torch

from ..geometry.topology import Topology, build_topology, vertex_areas
from .material import THICKNESS, Material

GRAVITY = (0.0, -9.81, 0.0)  # m/s^2, +Y up

# dG/dq_k for edges (0,1), (1,2), (2,0): G00 = q0, G11 = q2, G01 = (q0 + q2 - q1) / 2
_DG_DQ = torch.tensor([[[1.0, 0.5], [0.5, 0.0]],
                       [[0.0, -0.5], [-0.5, 0.0]],
                       [[0.0, 0.5], [0.5, 1.0]]], dtype=torch.float64)


@dataclass
class Rest:
    """Rest quantities derived from rest lengths and material (torch, float64), with the index arrays."""

    faces: torch.Tensor          # [F,3] long
    edges: torch.Tensor          # [E,2] long
    face_edges: torch.Tensor     # [F,3] long: edge joining corners k and k+1 of each face
    hinges: torch.Tensor         # [H,4] long
    rest_lengths: torch.Tensor   # [E]
    template: torch.Tensor       # [V,3] template positions (material directions live there)
    thickness: float
    face_rest_sq: torch.Tensor   # [F,3] rest squared lengths of the face edges
    face_area: torch.Tensor      # [F]
    strain_basis: torch.Tensor   # [F,3,2,2]  B_k with E = sum_k q_k B_k
    stretch_c: torch.Tensor      # [F,3,3]   StVK quadratic form in q
    mass: torch.Tensor           # [V]
    vertex_area: torch.Tensor    # [V] lumped template area
    hinge_coef: torch.Tensor     # [H]  energy = coef (theta - rest_angle)^2
    rest_angle: torch.Tensor     # [H]


@dataclass
class Numeric:
    """Numpy snapshot of a Cloth for the fast solver (parameters frozen)."""

    faces: np.ndarray
    edges: np.ndarray
    hinges: np.ndarray
    pairs: np.ndarray        # [P,2] Hessian off-diagonal pattern; pairs[:E] == edges
    face_pairs: np.ndarray   # [F,3] == face_edges
    hinge_pairs: np.ndarray  # [H,6]
    face_rest_sq: np.ndarray
    face_area: np.ndarray
    strain_basis: np.ndarray
    stretch_c: np.ndarray
    mass: np.ndarray
    vertex_area: np.ndarray
    hinge_coef: np.ndarray
    rest_angle: np.ndarray
    rest_lengths: np.ndarray
    sweep: tuple             # per-vertex CSR of pairs to lower / higher vertices (Gauss-Seidel sweeps)
    free: np.ndarray         # [V] 1.0 for simulated vertices, 0.0 for pinned ones
    template: np.ndarray
    thickness: float


@dataclass
class Cloth:
    """Template mesh + optimizable rest lengths and per-vertex material.

    rest_angles: dihedral rest angles per hinge; by default the template's own (so a curved template keeps its
    shape when unloaded, like Blender's angular bending); pass flat=True to bend towards flat (HOOD's choice).

    uniform_mass: every vertex carries the same share of the mass (density x the mean vertex area), as Blender's
    cloth gives each vertex its `mass` setting, instead of density x its own lumped area (a real fabric). On the
    benchmark skirt the two differ 4x at the hem ring; refitting air damping s5 (true alpha 10 /s) on every
    recording with each: alpha 11.3 /s (area) against 10.5 /s (uniform), free rollouts 5.92 against 5.51 mm; with
    nothing hidden it predicted held-out recordings no better (README, session 68), so it is not the default.
    """

    template: np.ndarray                 # [V,3] float64, metres, +Y up
    faces: np.ndarray                    # [F,3] int64
    material: Material | None = None
    rest_lengths: torch.Tensor | None = None
    pinned: np.ndarray | None = None     # [V] bool
    flat: bool = False
    thickness: float = THICKNESS
    uniform_mass: bool = False
    topology: Topology = field(init=False)

    def __post_init__(self) -> None:
        self.template = np.asarray(self.template, np.float64)
        self.faces = np.asarray(self.faces, np.int64)
        self.topology = build_topology(self.faces, len(self.template))
        if self.material is None:
            self.material = Material.uniform(self.n_vertices)
        if self.rest_lengths is None:
            e = self.topology.edges
            lengths = np.linalg.norm(self.template[e[:, 0]] - self.template[e[:, 1]], axis=1)
            self.rest_lengths = torch.from_numpy(lengths)
        if self.pinned is None:
            self.pinned = np.zeros(self.n_vertices, bool)

    @property
    def n_vertices(self) -> int:
        return len(self.template)

    @cached_property
    def template_angles(self) -> torch.Tensor:
        from .energies import dihedral_angles
        return dihedral_angles(torch.from_numpy(self.template), torch.from_numpy(self.topology.hinges))

    @cached_property
    def pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(pairs [P,2], hinge_pairs [H,6]): the off-diagonal Hessian blocks, the mesh edges (pair e = edge e) then
        the pairs of opposite hinge vertices; hinge_pairs[h] indexes the local pairs (0,1), (0,2), (1,2), (0,3),
        (1,3), (2,3). Keeping the opposite-vertex coupling of bending costs 2x in each CG iteration but was
        measured to cut the error after three Newton steps ~8x on a folding skirt: bending is the soft mode."""
        topo = self.topology
        n = self.n_vertices
        h = topo.hinges
        local = [(0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3)]
        a = np.stack([h[:, i] for i, _ in local], 1).reshape(-1)
        b = np.stack([h[:, j] for _, j in local], 1).reshape(-1)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        edge_keys = topo.edges[:, 0] * n + topo.edges[:, 1]
        extra = np.setdiff1d(np.unique(lo * n + hi), edge_keys)
        keys = np.concatenate([edge_keys, extra])
        pairs = np.stack([keys // n, keys % n], 1)
        order = np.argsort(keys)
        hinge_pairs = order[np.searchsorted(keys[order], lo * n + hi)].reshape(-1, 6)
        return pairs, hinge_pairs

    @cached_property
    def sweep(self) -> tuple[np.ndarray, ...]:
        """(lo_ptr, lo_pair, lo_nb, up_ptr, up_pair, up_nb): for each vertex, its Hessian pairs whose other vertex
        has a lower (resp. higher) index, as CSR, for the solver's Gauss-Seidel sweeps."""
        pairs, _ = self.pattern
        n = self.n_vertices
        out: list[np.ndarray] = []
        for row, nb in ((pairs[:, 1], pairs[:, 0]), (pairs[:, 0], pairs[:, 1])):
            order = np.argsort(row, kind="stable")
            ptr = np.zeros(n + 1, np.int64)
            np.cumsum(np.bincount(row, minlength=n), out=ptr[1:])
            out += [ptr, order.astype(np.int64), nb[order].astype(np.int64)]
        return tuple(out)

    def rest(self) -> Rest:
        topo = self.topology
        mat = self.material
        fe = torch.from_numpy(topo.face_edges)
        faces = torch.from_numpy(topo.faces)
        L = self.rest_lengths[fe]                             # [F,3] lengths of edges (0,1), (1,2), (2,0)
        l0, l1, l2 = L.unbind(-1)
        cos = ((l0 ** 2 + l2 ** 2 - l1 ** 2) / (2 * l0 * l2)).clamp(-0.9999, 0.9999)
        sin = torch.sqrt(1 - cos ** 2)
        zero = torch.zeros_like(l0)
        dm_inv = torch.stack([torch.stack([1 / l0, -cos / (l0 * sin)], -1),
                              torch.stack([zero, 1 / (l2 * sin)], -1)], -2)     # [F,2,2]
        area = 0.5 * l0 * l2 * sin
        basis = 0.5 * dm_inv.transpose(-1, -2).unsqueeze(1) @ _DG_DQ @ dm_inv.unsqueeze(1)   # [F,3,2,2]
        mu_f = mat.mu[faces].mean(-1)
        lam_f = mat.lam[faces].mean(-1)
        tr = basis.diagonal(dim1=-2, dim2=-1).sum(-1)                                    # [F,3]
        trbb = torch.einsum("fkab,flba->fkl", basis, basis)
        vol = self.thickness * area
        c = vol[:, None, None] * (mu_f[:, None, None] * trbb
                                  + 0.5 * lam_f[:, None, None] * tr[:, :, None] * tr[:, None, :])
        vertex_area = torch.from_numpy(vertex_areas(self.template, topo.faces))
        mass_area = vertex_area.mean().expand_as(vertex_area) if self.uniform_mass else vertex_area
        hinge_faces = torch.from_numpy(topo.hinge_faces)
        hinges = torch.from_numpy(topo.hinges)
        bend = mat.bending[hinges[:, :2]].mean(-1)
        le = self.rest_lengths[torch.from_numpy(topo.hinge_edges)]
        coef = bend * le ** 2 / (8 * area[hinge_faces].sum(-1))
        rest_angle = torch.zeros_like(coef) if self.flat else self.template_angles
        return Rest(faces=faces, edges=torch.from_numpy(topo.edges), face_edges=fe, hinges=hinges,
                    rest_lengths=self.rest_lengths,
                    template=torch.from_numpy(self.template), thickness=self.thickness,
                    face_rest_sq=L ** 2, face_area=area, strain_basis=basis, stretch_c=c,
                    mass=mat.density * mass_area, vertex_area=vertex_area, hinge_coef=coef, rest_angle=rest_angle)

    def numeric(self) -> Numeric:
        with torch.no_grad():
            rest = self.rest()
        pairs, hinge_pairs = self.pattern
        topo = self.topology

        def np64(t: torch.Tensor) -> np.ndarray:
            return np.ascontiguousarray(t.detach().numpy(), dtype=np.float64)

        return Numeric(faces=topo.faces, edges=topo.edges, hinges=topo.hinges, pairs=pairs,
                       face_pairs=topo.face_edges, hinge_pairs=hinge_pairs, sweep=self.sweep,
                       face_rest_sq=np64(rest.face_rest_sq),
                       face_area=np64(rest.face_area), strain_basis=np64(rest.strain_basis),
                       stretch_c=np64(rest.stretch_c), mass=np64(rest.mass), vertex_area=np64(rest.vertex_area),
                       hinge_coef=np64(rest.hinge_coef), rest_angle=np64(rest.rest_angle),
                       rest_lengths=np64(self.rest_lengths), free=(~self.pinned).astype(np.float64),
                       template=self.template, thickness=self.thickness)
