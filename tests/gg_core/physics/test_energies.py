"""Every energy term: torch gradients against finite differences, the fast numpy/numba path against torch,
Hessian approximations PSD and exact where the energy is convex, StVK in q-form against the F-based formula."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from gg_core.physics.cloth import Cloth
from gg_core.physics.energies import Bending, Collision, Inertia, Stretching
from gg_core.physics.forces import TERMS
from gg_core.physics.terms import System

from physics_helpers import random_step, triangle_lattice

# non-default parameters so that every term is active
PARAMS = {"wind": {"velocity": (1.0, 0.5, 2.0)}, "anisotropic_stretch": {"k_weft": 1.0e4},
          "gravity_offset": {"delta_g": (0.3, -0.2, 0.1)}}


def make(name: str):
    return TERMS[name](**PARAMS.get(name, {}))


def dense_hessian(system: System) -> np.ndarray:
    n = len(system.hdiag)
    h = np.zeros((3 * n, 3 * n))
    for i in range(n):
        h[3 * i:3 * i + 3, 3 * i:3 * i + 3] = system.hdiag[i]
    for p, (i, j) in enumerate(system.num.pairs):
        h[3 * i:3 * i + 3, 3 * j:3 * j + 3] += system.hpair[p]
        h[3 * j:3 * j + 3, 3 * i:3 * i + 3] += system.hpair[p].T
    return h


def assemble(term, x, step, cloth) -> tuple[float, System]:
    num = cloth.numeric()
    system = System(num)
    energy = term.assemble(x, step, num, system)
    system.finalize(x)
    return energy, system


@pytest.mark.parametrize("name", list(TERMS))
def test_gradient_matches_finite_differences(name, cloth, state):
    x, step = state
    term, rest, st = make(name), cloth.rest(), step.to_torch()
    xt = torch.tensor(x, requires_grad=True)
    (grad,) = torch.autograd.grad(term.energy(xt, st, rest), xt)
    rng = np.random.default_rng(3)
    for _ in range(3):
        d = rng.normal(size=x.shape)
        h = 1e-6
        fd = (term.energy(torch.tensor(x + h * d), st, rest) - term.energy(torch.tensor(x - h * d), st, rest)) / (2 * h)
        analytic = float((grad.numpy() * d).sum())
        assert abs(float(fd) - analytic) <= 1e-6 * max(abs(analytic), 1e-8) + 1e-12, (name, float(fd), analytic)


@pytest.mark.parametrize("name", list(TERMS))
def test_fast_path_matches_torch(name, cloth, state):
    x, step = state
    term = make(name)
    energy, system = assemble(term, x, step, cloth)
    xt = torch.tensor(x, requires_grad=True)
    e_t = term.energy(xt, step.to_torch(), cloth.rest())
    (grad,) = torch.autograd.grad(e_t, xt)
    assert energy == pytest.approx(e_t.item(), rel=1e-10, abs=1e-14)
    np.testing.assert_allclose(system.grad, grad.numpy(), rtol=1e-9, atol=1e-12 * np.abs(grad.numpy()).max())


@pytest.mark.parametrize("name", list(TERMS))
def test_hessian_approximation_is_psd(name, cloth, state):
    x, step = state
    _, system = assemble(make(name), x, step, cloth)
    h = dense_hessian(system)
    np.testing.assert_allclose(h, h.T, atol=1e-12 * max(np.abs(h).max(), 1e-30))
    assert np.linalg.eigvalsh(h).min() >= -1e-9 * max(np.abs(h).max(), 1e-30)


def torch_hessian(term, x, step, cloth) -> np.ndarray:
    rest, st = cloth.rest(), step.to_torch()
    h = torch.autograd.functional.hessian(lambda y: term.energy(y.view(-1, 3), st, rest), torch.tensor(x).reshape(-1))
    return h.numpy()


def test_stretching_hessian_exact_in_tension():
    """Uniformly stretched acute triangles put every edge in tension, so the dropped compressive curvature is
    zero and the assembled Hessian is the exact one."""
    verts, faces = triangle_lattice(3, 3, 0.05)
    cloth = Cloth(verts, faces)
    x = verts * 1.05 + np.array([0.0, 0.01, 0.0])
    step = random_step(cloth, verts)
    _, system = assemble(Stretching(), x, step, cloth)
    assert (system.face_dpsi > 0).all()
    ref = torch_hessian(Stretching(), x, step, cloth)
    np.testing.assert_allclose(dense_hessian(system), ref, rtol=1e-8, atol=1e-8 * np.abs(ref).max())


def test_bending_hessian_exact_at_rest_angles(cloth, state):
    """At the rest angles the Gauss-Newton bending Hessian is the exact one."""
    _, step = state
    x = cloth.template.copy()
    _, system = assemble(Bending(), x, step, cloth)
    ref = torch_hessian(Bending(), x, step, cloth)
    np.testing.assert_allclose(dense_hessian(system), ref, rtol=1e-7, atol=1e-7 * np.abs(ref).max())


@pytest.mark.parametrize("term", [Inertia(), Collision()])
def test_vertex_term_hessian_exact(term, cloth, state):
    x, step = state
    _, system = assemble(term, x, step, cloth)
    ref = torch_hessian(term, x, step, cloth)
    np.testing.assert_allclose(dense_hessian(system), ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_stvk_q_form_matches_deformation_gradient(cloth, state):
    """psi = q^T C q equals the textbook V (mu tr E^2 + lam/2 tr^2 E), E = (F^T F - I)/2, F = Ds Dm^-1."""
    x, step = state
    tmpl = cloth.template[cloth.faces]
    t1 = tmpl[:, 1] - tmpl[:, 0]
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    n = np.cross(tmpl[:, 1] - tmpl[:, 0], tmpl[:, 2] - tmpl[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    t2 = np.cross(n / (2 * area[:, None]), t1)
    dm = np.stack([np.stack([((tmpl[:, k] - tmpl[:, 0]) * t).sum(1) for k in (1, 2)], 1) for t in (t1, t2)], 1)
    cur = x[cloth.faces]
    ds = np.stack([cur[:, 1] - cur[:, 0], cur[:, 2] - cur[:, 0]], 2)
    f = ds @ np.linalg.inv(dm)
    e = 0.5 * (np.transpose(f, (0, 2, 1)) @ f - np.eye(2))
    mat = cloth.material
    mu = mat.mu.numpy()[cloth.faces].mean(1)
    lam = mat.lam.numpy()[cloth.faces].mean(1)
    tr = np.trace(e, axis1=1, axis2=2)
    ref = (cloth.thickness * area * (mu * np.einsum("fab,fba->f", e, e) + 0.5 * lam * tr * tr)).sum()
    got = float(Stretching().energy(torch.tensor(x), step.to_torch(), cloth.rest()))
    assert got == pytest.approx(ref, rel=1e-10)


def test_energy_gradient_wrt_material_and_rest_lengths(cloth, state):
    """Fitting differentiates the energy gradient in x with respect to material and rest lengths: check the
    derivative of (grad_x E . v) by finite differences in each parameter family."""
    x, step = state
    st = step.to_torch()
    terms = [TERMS[n]() for n in ("inertia", "gravity", "stretching", "bending", "collision")]
    v = torch.tensor(np.random.default_rng(4).normal(size=x.shape))
    params = {"mu": cloth.material.mu, "density": cloth.material.density, "bending": cloth.material.bending,
              "lam": cloth.material.lam, "rest_lengths": cloth.rest_lengths}

    def objective(c: Cloth) -> torch.Tensor:
        xt = torch.tensor(x, requires_grad=True)
        energy = sum(t.energy(xt, st, c.rest()) for t in terms)
        (g,) = torch.autograd.grad(energy, xt, create_graph=True)
        return (g * v).sum()

    for name, value in params.items():
        p = value.clone().requires_grad_(True)
        c = _with(cloth, name, p)
        (dp,) = torch.autograd.grad(objective(c), p)
        d = torch.tensor(np.random.default_rng(5).normal(size=p.shape)) * p.detach().abs()
        h = 1e-6
        plus, minus = (objective(_with(cloth, name, p.detach() + s * h * d)) for s in (1, -1))
        fd = (plus - minus) / (2 * h)
        assert fd.item() == pytest.approx((dp * d).sum().item(), rel=1e-5, abs=1e-12), name


def _with(cloth: Cloth, name: str, value: torch.Tensor) -> Cloth:
    import copy

    c = copy.copy(cloth)
    if name == "rest_lengths":
        c.rest_lengths = value
    else:
        c.material = copy.copy(cloth.material)
        setattr(c.material, name, value)
    return c
