"""Analytic test scenes: a ring of cameras around a sphere or a textured plane, with exact masks and images."""
from __future__ import annotations

import numpy as np
import trimesh

from gg_core.capture.cameras import Camera, look_at


def ring_cameras(n: int, radius: float = 2.0, height: float = 0.5, size: tuple[int, int] = (64, 64),
                 fov: float = 40.0, target=(0.0, 0.0, 0.0)) -> list[Camera]:
    cams = []
    for i in range(n):
        a = 2 * np.pi * i / n
        eye = np.array([radius * np.sin(a), height, radius * np.cos(a)])
        cams.append(look_at(f"c{i}", eye, np.asarray(target, float), fov, size[0], size[1], index=i))
    return cams


def pixel_rays(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(origin [3], unit directions [H*W, 3]) through the pixel centres, rows top-down."""
    xs, ys = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    pix = np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)], axis=1)
    d = (np.linalg.inv(cam.K) @ pix.T).T @ cam.R
    return cam.center, d / np.linalg.norm(d, axis=1, keepdims=True)


def sphere_mask(cam: Camera, centre: np.ndarray, radius: float) -> np.ndarray:
    origin, d = pixel_rays(cam)
    oc = origin - centre
    b = d @ oc
    disc = b ** 2 - (oc @ oc - radius ** 2)
    return (disc >= 0).reshape(cam.height, cam.width)


def sphere_mesh(radius: float, subdivisions: int = 3, centre=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + centre, np.asarray(m.faces, np.int64)


def plane_texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """[N, 3] smooth random-looking colours on the plane z = 0 (sums of sines, features of a few cm)."""
    rng = np.random.default_rng(3)
    out = np.zeros((len(x), 3))
    for c in range(3):
        for _ in range(6):
            k = rng.uniform(40, 120, 2) * rng.choice([-1, 1], 2)
            out[:, c] += np.sin(k[0] * x + k[1] * y + rng.uniform(0, 6.3))
    return 0.5 + 0.08 * out


def plane_image(cam: Camera) -> np.ndarray:
    """[H, W, 3] image of the textured plane z = 0 (every ray is assumed to hit it)."""
    origin, d = pixel_rays(cam)
    t = -origin[2] / d[:, 2]
    hit = origin + t[:, None] * d
    return plane_texture(hit[:, 0], hit[:, 1]).reshape(cam.height, cam.width, 3)


def cylinder_image(cam: Camera, radius: float, background: float = 0.2) -> np.ndarray:
    """[H, W, 3] image of the textured cylinder x^2 + z^2 = radius^2 around the y axis, seen from the +z side
    (plane_texture over arc length and height, so the texture is undistorted on the surface)."""
    origin, d = pixel_rays(cam)
    a = d[:, 0] ** 2 + d[:, 2] ** 2
    b = 2 * (origin[0] * d[:, 0] + origin[2] * d[:, 2])
    disc = b * b - 4 * a * (origin[0] ** 2 + origin[2] ** 2 - radius ** 2)
    hit = origin + ((-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * a))[:, None] * d
    image = plane_texture(radius * np.arctan2(hit[:, 0], hit[:, 2]), hit[:, 1])
    image[disc < 0] = background
    return image.reshape(cam.height, cam.width, 3)
