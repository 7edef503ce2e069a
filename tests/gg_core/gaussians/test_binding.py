"""Binding: face frames and scales, rigid/scale covariance, gradients to vertices through rendering."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from gg_core.capture.cameras import look_at
from gg_core.gaussians import texture as tex
from gg_core.gaussians.binding import bind, face_frames, face_scale
from gg_core.gaussians.render import render
from gg_core.gaussians.rotations import quat_to_rotmat


@pytest.fixture(scope="module")
def garment():
    m = trimesh.creation.icosphere(subdivisions=1, radius=0.4)
    verts, faces = np.asarray(m.vertices), np.asarray(m.faces)
    t = tex.build_texture(verts, faces, resolution=24)
    g = torch.Generator().manual_seed(0)
    t.params = t.params.double() + 0.3 * torch.randn(t.params.shape, generator=g, dtype=torch.float64)
    return verts, faces, t


def test_face_frame_and_scale_of_a_known_triangle():
    verts = torch.tensor([[0.0, 0, 0], [2, 0, 0], [0.5, 0, -1]], dtype=torch.float64)
    faces = torch.tensor([[0, 1, 2]])
    # a0 = x (the edge v1 - v0), a1 = x cross (v2 - v0) = +y, a2 = a0 cross a1 = +z
    assert torch.allclose(face_frames(verts, faces)[0], torch.eye(3, dtype=torch.float64))
    assert torch.allclose(face_scale(verts, faces), torch.tensor([1.5], dtype=torch.float64))  # (2 + 1) / 2


def test_gaussians_follow_rigid_motion_and_uniform_scale_exactly(garment):
    verts, faces, t = garment
    base = bind(t, torch.tensor(verts), faces)
    R = Rotation.from_euler("xyz", [0.3, -1.1, 2.0]).as_matrix()
    shift, c = np.array([0.2, -1.0, 3.0]), 1.7
    moved = bind(t, torch.tensor(c * verts @ R.T + shift), faces)
    Rt = torch.tensor(R)
    assert torch.allclose(moved.means, c * base.means @ Rt.T + torch.tensor(shift), atol=1e-12)
    assert torch.allclose(moved.scales, c * base.scales, atol=1e-12)
    assert torch.allclose(quat_to_rotmat(moved.quats), Rt @ quat_to_rotmat(base.quats), atol=1e-12)
    assert torch.equal(moved.opacities, base.opacities) and torch.equal(moved.sh, base.sh)


def test_offsets_are_in_face_units_along_the_frame(garment):
    verts, faces, t = garment
    on_surface, along_normal = t.params.clone(), t.params.clone()
    on_surface[:, tex.OFFSET] = 0.0
    along_normal[:, tex.OFFSET] = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)  # local y is the normal
    v = torch.tensor(verts)
    g0, g1 = bind(t, v, faces, on_surface), bind(t, v, faces, along_normal)
    normals = torch.tensor(trimesh.Trimesh(verts, faces, process=False).face_normals)[t.face_ids]
    k = face_scale(v, torch.tensor(faces))[t.face_ids]
    assert torch.allclose(g1.means - g0.means, k[:, None] * normals, atol=1e-12)


def _fd_check(loss, x: torch.Tensor, h: float = 1e-6) -> float:
    """Relative error between autograd and central differences of loss(x) over every entry of x."""
    x = x.detach().clone().requires_grad_(True)
    loss(x).backward()
    numeric = torch.zeros_like(x)
    with torch.no_grad():
        flat = x.detach().clone().view(-1)
        for i in range(flat.numel()):
            old = flat[i].item()
            flat[i] = old + h
            up = loss(flat.view_as(x)).item()
            flat[i] = old - h
            numeric.view(-1)[i] = (up - loss(flat.view_as(x)).item()) / (2 * h)
            flat[i] = old
    assert numeric.norm() > 0
    return float((numeric - x.grad).norm() / numeric.norm())


def test_gradients_through_binding_and_rendering_match_finite_differences(garment):
    """Vertex positions and all 59 texture channels (SH, opacity, scale, rotation, offset)."""
    verts, faces, t = garment
    cam = look_at("c", np.array([0.3, 0.2, -1.5]), np.zeros(3), 50, 20, 16)
    weights = torch.tensor(np.random.default_rng(1).random((16, 20, 3)))

    def loss_of(v, params):
        out = render(bind(t, v, faces, params), cam, (0.2, 0.3, 0.4))
        return (out["image"] * weights).sum() + out["depth"].sum() * 0.1

    v0 = torch.tensor(verts)
    assert _fd_check(lambda v: loss_of(v, t.params), v0) < 1e-3
    few = torch.arange(0, len(t), max(1, len(t) // 12))  # a dozen Gaussians spread over the sphere
    params = t.params.clone()

    def loss_params(sub):
        full = params.clone()
        full[few] = sub
        return loss_of(v0, full)

    sub = params[few]
    for name, channels in (("sh", tex.SH), ("opacity", slice(tex.OPACITY, tex.OPACITY + 1)),
                           ("scale", tex.LOG_SCALE), ("rotation", tex.ROTATION), ("offset", tex.OFFSET)):
        def loss_channels(x, channels=channels):
            y = sub.clone()
            y[:, channels] = x
            return loss_params(y)

        assert _fd_check(loss_channels, sub[:, channels]) < 1e-3, name
