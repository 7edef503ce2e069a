"""Layered visibility: Gaussians behind another mesh are dropped, the rest are kept."""
from __future__ import annotations

import numpy as np
import torch
import trimesh

from gg_core.capture.cameras import look_at
from gg_core.gaussians import texture as tex
from gg_core.gaussians.binding import bind, surface_points
from gg_core.gaussians.render import render
from gg_core.gaussians.visibility import visible_mask
from gg_core.geometry.raycast import RayCaster

INNER = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
CAM = look_at("c", np.array([0, 0, -2.0]), np.zeros(3), 40, 32, 32)


def _inner_points(t):
    return surface_points(t, torch.tensor(INNER.vertices), INNER.faces).numpy()


def test_panel_in_front_hides_exactly_the_gaussians_behind_it():
    t = tex.build_texture(INNER.vertices, INNER.faces, resolution=32)
    points = _inner_points(t)
    # an outer layer panel at z = -0.5 covering x in [0, 1]: analytically, where does each camera ray cross it?
    panel = (np.array([[0, -1, -0.5], [1, -1, -0.5], [1, 1, -0.5], [0, 1, -0.5]]), np.array([[0, 1, 2], [0, 2, 3]]))
    s = (-0.5 - CAM.center[2]) / (points[:, 2] - CAM.center[2])
    crossing = CAM.center + s[:, None] * (points - CAM.center)
    behind = (crossing[:, 0] > 0) & (np.abs(crossing[:, 1]) < 1)
    clear = np.abs(crossing[:, 0]) > 1e-3  # skip rays grazing the panel edge
    visible = visible_mask(points, CAM, RayCaster([panel]))
    assert behind[clear].any() and (~behind[clear]).any()
    assert np.array_equal(visible[clear], ~behind[clear])


def test_closed_outer_layer_hides_everything_and_no_occluder_hides_nothing():
    t = tex.face_texture(INNER.vertices, INNER.faces)
    points = _inner_points(t)
    outer = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
    assert not visible_mask(points, CAM, RayCaster([(outer.vertices, outer.faces)])).any()
    assert visible_mask(points, CAM, None).all()


def test_visible_subset_renders_and_backpropagates_to_the_mesh():
    t = tex.face_texture(INNER.vertices, INNER.faces)
    panel = (np.array([[0, -1, -0.5], [1, -1, -0.5], [1, 1, -0.5], [0, 1, -0.5]]), np.array([[0, 1, 2], [0, 2, 3]]))
    visible = torch.from_numpy(visible_mask(_inner_points(t), CAM, RayCaster([panel])))
    verts = torch.tensor(INNER.vertices, requires_grad=True)
    out = render(bind(t, verts, INNER.faces)[visible], CAM)
    out["image"].sum().backward()
    alpha = out["alpha"].detach()
    # the sphere spans columns 8..23; the panel covers its +x half, the image's left half (camera x = world -x)
    assert alpha[12:20, 18:23].mean() > 0.5 and alpha[:, :12].max() == 0
    assert verts.grad.abs().sum() > 0
