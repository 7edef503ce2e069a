"""A small synthetic scene for the fitting tests: a curved textured sheet seen by a ring of cameras, the target
images rendered with the product's own rasterizer (so the true mesh and texture are known exactly)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import torch

from gg_core.capture.cameras import Camera, look_at
from gg_core.gaussians import face_texture, rgb_to_sh0
from gg_core.gaussians.texture import LOG_SCALE, GaussianTexture
from gg_core.registration.photometric import render_view
from gg_core.registration.views import View

BACKGROUND = torch.tensor([1.0, 1.0, 0.0])


@dataclass
class SheetScene:
    verts: np.ndarray        # true vertex positions
    faces: np.ndarray
    texture: GaussianTexture  # true appearance
    cameras: list[Camera]
    views: list[View]        # rendered at the true mesh; garment = alpha > 0.5, background elsewhere


def curved_sheet(n: int = 9, size: float = 0.4, radius: float = 0.35) -> tuple[np.ndarray, np.ndarray]:
    """A patch of a vertical cylinder (bent around +y), normals facing +z (towards the front camera)."""
    u, v = np.meshgrid(np.linspace(-0.5, 0.5, n), np.linspace(-0.5, 0.5, n), indexing="ij")
    angle = u.ravel() * size / radius
    verts = np.stack((radius * np.sin(angle), v.ravel() * size + 1.0, radius * np.cos(angle) - radius), 1)
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            faces += [[a, d, c], [a, c, b]]
    return verts, np.array(faces)


def render_views(texture: GaussianTexture, verts: np.ndarray, faces: np.ndarray, cameras: list[Camera]) -> list[View]:
    views = []
    for cam in cameras:
        blank = View(cam, torch.zeros(cam.height, cam.width, 3), torch.zeros(cam.height, cam.width),
                     torch.ones(cam.height, cam.width))
        with torch.no_grad():
            out = render_view(texture, torch.from_numpy(verts).float(), faces, blank, BACKGROUND)
        garment = (out["alpha"] > 0.5).float()
        views.append(View(cam, out["image"].float(), garment, 1 - garment))
    return views


@pytest.fixture(scope="session")
def sheet_scene() -> SheetScene:
    verts, faces = curved_sheet()
    texture = face_texture(verts, faces, opacity=0.95)
    c = verts[faces].mean(1)                    # smooth colour waves (~13 cm) so each face's pixels agree
    rgb = 0.5 + 0.35 * np.stack((np.sin(48 * c[:, 0]), np.cos(48 * c[:, 1]), np.sin(34 * (c[:, 0] + c[:, 1]))), 1)
    texture.params[:, 0:3] = rgb_to_sh0(torch.from_numpy(rgb).float())
    texture.params[:, LOG_SCALE] -= float(np.log(2.5))   # sigma ~ face size / 2.5: neighbours overlap, not blur
    cameras = [look_at(f"c{i}", np.array([1.2 * np.sin(a), 1.1, 1.2 * np.cos(a)]), np.array([0, 1.0, -0.05]),
                       40, 48, 40, index=i) for i, a in enumerate(np.radians([-40, -10, 20, 50]))]
    return SheetScene(verts, faces, texture, cameras, render_views(texture, verts, faces, cameras))
