"""Registration losses: gradients against finite differences (float64) and analytic cases."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from gg_core.physics.contact import BodyCollider
from gg_core.physics.material import MATERIAL_SPEC, THICKNESS
from gg_core.registration.losses import BODY_EPS, Bending, BodyTerm, Contacts, Strain, body_loss, virtual_edges


def grid(n: int = 4, size: float = 0.1, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """An n x n vertex grid in the plane z, normals +z (counter-clockwise faces seen from +z)."""
    u = np.linspace(0, size, n)
    xx, yy = np.meshgrid(u, u, indexing="ij")
    verts = np.stack((xx.ravel(), yy.ravel(), np.full(n * n, z)), 1)
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            faces += [[a, b, c], [a, c, d]]
    return verts, np.array(faces)


def bumpy(verts: np.ndarray, seed: int = 0) -> np.ndarray:
    return verts + np.random.default_rng(seed).normal(0, 0.004, verts.shape)


def test_gradients_match_finite_differences():
    verts, faces = grid()
    bend, strain = Bending(verts, faces), Strain(verts, faces)
    rest = bumpy(verts, 1)
    bend.set_rest(bend.angles(rest))
    strain.set_rest(strain.lengths(rest))
    x = torch.tensor(bumpy(verts, 2), requires_grad=True)
    assert torch.autograd.gradcheck(bend, (x,), eps=1e-7, atol=1e-6, rtol=1e-4)
    assert torch.autograd.gradcheck(strain, (x,), eps=1e-7, atol=1e-8, rtol=1e-4)
    contacts = Contacts(torch.zeros_like(x), torch.tensor([[0.0, 0.0, 1.0]]).expand_as(x).clone(),
                        torch.ones(len(x), dtype=torch.float64))
    below = torch.tensor(bumpy(verts, 3) - [0, 0, 0.002], requires_grad=True)
    assert torch.autograd.gradcheck(lambda p: body_loss(p, contacts), (below,), eps=1e-7, atol=1e-10, rtol=1e-4)


def test_bending_is_zero_at_rest_and_quadratic_in_the_fold():
    # two triangles sharing the edge (0,0,0)-(1,0,0): fold the second by theta about that edge
    verts = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]], float)
    faces = np.array([[0, 1, 2], [1, 0, 3]])
    bend = Bending(verts, faces)
    assert float(bend(torch.from_numpy(verts))) == pytest.approx(0.0, abs=1e-15)
    theta = 0.3
    folded = verts.copy()
    folded[3] = [0.5, -np.cos(theta), np.sin(theta)]
    weight = 1.0 / (0.5 + 0.5)                     # |e|^2 / (A_a + A_b) of the rest shape
    assert float(bend(torch.from_numpy(folded))) == pytest.approx(weight * theta ** 2, rel=1e-9)
    # a rigidly moved rest shape costs nothing
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    assert float(bend(torch.from_numpy(verts @ R.T + 3.0))) == pytest.approx(0.0, abs=1e-12)


def test_strain_of_a_uniform_stretch_matches_stvk():
    verts, faces = grid(5, 0.2)
    strain = Strain(verts, faces)
    s = 1.05
    g = 0.5 * (s * s - 1)                          # G = g I for a uniform in-plane stretch
    mu, lam = MATERIAL_SPEC["mu"][0], MATERIAL_SPEC["lam"][0]
    expected = THICKNESS * 0.2 * 0.2 * (lam / 2 * (2 * g) ** 2 + mu * 2 * g * g)
    assert float(strain(torch.from_numpy(verts * s))) == pytest.approx(expected, rel=1e-9)
    assert float(strain(torch.from_numpy(verts + 1.0))) == pytest.approx(0.0, abs=1e-20)


def test_body_loss_is_cubic_inside_the_margin_and_zero_outside():
    body_v, body_f = grid(41, 1.0)                  # vertices 2.5 cm apart: nearest-vertex search within reach
    body_v -= [0.5, 0.5, 0]                         # a flat body patch in z = 0, normal +z, around the origin
    collider = BodyCollider(body_f, len(body_v))
    term = BodyTerm(collider, body_v)
    x = torch.tensor([[0.01, 0.02, 0.001], [0.0, -0.1, 0.01], [0.05, 0.05, -0.002]])
    contacts = term.contacts(x)
    assert contacts.active.tolist() == [1.0, 1.0, 1.0]
    expected = (BODY_EPS - 0.001) ** 3 + (BODY_EPS + 0.002) ** 3   # the middle point is 1 cm out: no cost
    assert float(term(x.double(), Contacts(contacts.points.double(), contacts.normals.double(),
                                           contacts.active.double()))) == pytest.approx(expected, rel=1e-6)


def test_virtual_edges_link_facing_sheets_and_cost_only_compression():
    top, faces = grid(4, 0.1, z=0.05)
    bottom, bottom_faces = grid(7, 0.2, z=-0.05)
    bottom -= [0.05, 0.05, 0]                       # larger than the top sheet: every top ray lands inside it
    verts = np.concatenate((top, bottom))
    # normals point away from the gap (up on the top sheet, down on the bottom one), like the outside of a tube:
    # a ray along -n from either sheet crosses the gap and hits the other one, whose normal is opposite
    all_faces = np.concatenate((faces, bottom_faces[:, ::-1] + len(top)))
    edges = virtual_edges(verts, all_faces)
    assert set(range(len(top))) <= set(edges.vertex.tolist())
    assert np.allclose(edges.rest.numpy(), 0.1)
    x = torch.from_numpy(verts)
    assert float(edges(x)) == pytest.approx(0.0, abs=1e-20)
    apart = x.clone()
    apart[: len(top), 2] += 0.02
    assert float(edges(apart)) == pytest.approx(0.0, abs=1e-20)        # stretching is free
    closer = x.clone()
    closer[: len(top), 2] -= 0.02
    assert float(edges(closer)) == pytest.approx(len(edges) * 0.02 ** 2, rel=1e-9)


def test_virtual_edges_skip_sheets_that_do_not_face_each_other():
    top, faces = grid(4, 0.1, z=0.05)
    bottom = top - [0, 0, 0.1]
    verts = np.concatenate((top, bottom))
    same_way = np.concatenate((faces, faces + len(top)))      # both sheets' normals point +z
    assert len(virtual_edges(verts, same_way)) == 0
