"""Base terms of the incremental potential: inertia, gravity, StVK stretching, dihedral bending, body collision.

Formulas (REFERENCE.md §5, HOOD/ContourCraft):
- inertia    sum_i m_i / (2 dt^2) |x_i - (x_t + dt v_t)_i|^2
- gravity    -sum_i m_i g . x_i
- stretching sum_f V_f (mu tr(E^2) + lam/2 tr(E)^2), E the Green strain against the 2D rest shape, V = area x
             thickness (written as q^T C q, see cloth.py)
- bending    sum_h k_h l_h^2 / (8 (A_a + A_b)) (theta_h - theta_rest)^2 with rest edge length l and rest face areas
             (HOOD: bending_coeff l^2 / (4 a) theta^2 / 2)
- collision  sum_i k A_i max(eps - (x_i - c_i) . n_i, 0)^3 against the body plane (c, n) at the end of the step;
             scaled by the vertex area A_i so the contact pressure does not depend on mesh resolution.
"""
from __future__ import annotations

import numpy as np
import torch

from . import kernels
from .cloth import GRAVITY
from .terms import Term


def face_q(x: torch.Tensor, faces: torch.Tensor, rest_sq: torch.Tensor) -> torch.Tensor:
    """[..., F, 3] squared edge lengths minus rest squared lengths, edge k joining corners k and k+1."""
    a = x[..., faces, :]                     # [..., F, 3, 3]
    d = a - a.roll(-1, dims=-2)
    return (d * d).sum(-1) - rest_sq


def dihedral_angles(x: torch.Tensor, hinges: torch.Tensor) -> torch.Tensor:
    """Signed angle between the two face normals of each hinge (0 = flat), [..., H]."""
    x0, x1, x2, x3 = (x[..., hinges[:, k], :] for k in range(4))
    e = x1 - x0
    na = torch.cross(e, x2 - x0, dim=-1)
    nb = torch.cross(x3 - x0, e, dim=-1)
    sin = (torch.cross(na, nb, dim=-1) * e).sum(-1) / e.norm(dim=-1)
    return torch.atan2(sin, (na * nb).sum(-1))


def vertex_normals(x: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals [V,3] (numpy)."""
    return kernels.vertex_normals(np.ascontiguousarray(x, np.float64), faces)


class Inertia(Term):
    """Kinetic part of implicit Euler: mass times the squared deviation from the inertial prediction x_t + dt v_t,
    over 2 dt^2. Its minimizer with the other terms is the backward-Euler step."""

    name = "inertia"

    def energy(self, x, step, rest):
        d = x - step.x_inertial
        return (rest.mass * (d * d).sum(-1)).sum(-1) / (2 * step.dt ** 2)

    def assemble(self, x, step, num, system):
        d = x - step.x_inertial
        w = num.mass / step.dt ** 2
        if system is not None:
            system.add_vertex(w[:, None] * d, iso=w)
        return float(0.5 * (w * (d * d).sum(1)).sum())


class Gravity(Term):
    """Uniform gravitational field g (m/s^2) acting on the vertex masses."""

    name = "gravity"
    defaults = {"g": GRAVITY}

    def energy(self, x, step, rest):
        return -(rest.mass * (x * self.params["g"]).sum(-1)).sum(-1)

    def assemble(self, x, step, num, system):
        mg = num.mass[:, None] * self.p("g")
        if system is not None:
            system.add_vertex(-mg)
        return float(-(mg * x).sum())


class Stretching(Term):
    """In-plane elasticity: isotropic St. Venant-Kirchhoff membrane with per-vertex Lame mu and lambda (averaged
    per face) and the fabric thickness, against each face's rest shape."""

    name = "stretching"

    def energy(self, x, step, rest):
        q = face_q(x, rest.faces, rest.face_rest_sq)
        return torch.einsum("...fk,fkl,...fl->...", q, rest.stretch_c, q)

    def assemble(self, x, step, num, system):
        if system is None:
            return kernels.quadratic_q(x, num.faces, num.face_rest_sq, num.stretch_c, False, np.empty((0, 3)))
        energy = kernels.quadratic_q(x, num.faces, num.face_rest_sq, num.stretch_c, True, system.face_dpsi)
        system.add_face_q(None, 2.0 * num.stretch_c)
        return energy


class Bending(Term):
    """Out-of-plane stiffness: discrete-shell dihedral bending with per-vertex coefficient (averaged over each
    hinge edge) towards the rest dihedral angles."""

    name = "bending"

    def energy(self, x, step, rest):
        d = dihedral_angles(x, rest.hinges) - rest.rest_angle
        return (rest.hinge_coef * d * d).sum(-1)

    def assemble(self, x, step, num, system):
        if system is None:
            return float(kernels.hinge_energy(x, num.hinges, num.hinge_coef, num.rest_angle))
        return float(kernels.hinge_assemble(x, num.hinges, num.hinge_pairs, num.hinge_coef, num.rest_angle,
                                            system.grad, system.hdiag, system.hpair))


class Collision(Term):
    """Body contact: cubic penalty on each vertex closer than `margin` (m) to the body plane at the end of the
    step, stiffness `stiffness` (J/m^5, times the vertex area). Vertices that start inside are pushed out."""

    name = "collision"
    defaults = {"stiffness": 1.0e7, "margin": 3.0e-3}

    def energy(self, x, step, rest):
        gap = self.params["margin"] - ((x - step.contact_point) * step.contact_normal).sum(-1)
        g = torch.clamp(gap, min=0.0) * step.contact_active
        return (self.params["stiffness"] * rest.vertex_area * g ** 3).sum(-1)

    def assemble(self, x, step, num, system):
        n = step.contact_normal
        gap = self.p("margin") - ((x - step.contact_point) * n).sum(1)
        g = np.maximum(gap, 0.0) * step.contact_active
        k = self.p("stiffness") * num.vertex_area
        if system is not None:
            system.add_vertex(-(3 * k * g * g)[:, None] * n,
                              hess=(6 * k * g)[:, None, None] * n[:, :, None] * n[:, None, :])
        return float((k * g ** 3).sum())

    def normal_force(self, signed_distance: np.ndarray, vertex_area: np.ndarray) -> np.ndarray:
        """Penalty force magnitude (N) at the given distances: the normal force friction uses."""
        g = np.maximum(self.p("margin") - signed_distance, 0.0)
        return 3 * self.p("stiffness") * vertex_area * g * g


BASE_TERMS: tuple[type[Term], ...] = (Inertia, Gravity, Stretching, Bending, Collision)
