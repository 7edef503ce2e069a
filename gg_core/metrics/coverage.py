"""How many cameras see each part of a ground-truth surface: what any multi-view reconstruction can triangulate.

A point seen by fewer than two cameras has no stereo match; only a prior (smoothness, the silhouettes' hull) can
place it. The share of such points is a ceiling on the recall any photo-consistency method reaches, so template
reports carry it next to the F-score. Measured on the demo capture (00_walk frame 0, 12 cameras, 192x256 px):
4.1 / 5.4 / 8.0 % of the true skirt is seen by fewer than two cameras facing it within 84 / 73 / 60 degrees,
9.7 / 11.8 / 17.1 % of its lowest fifth (the hem's folds hide each other and are hidden by the legs).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..capture.cameras import Camera
from ..geometry.raycast import RayCaster
from .surface import sample_faces

COSINES = (0.1, 0.3, 0.5)   # cameras facing the surface within ~84, ~73 and 60 degrees
LIFT = 0.002                # m off the surface towards the camera, so a ray does not hit its own triangle


def camera_counts(verts: np.ndarray, faces: np.ndarray, cameras: Sequence[Camera],
                  occluders: Sequence[tuple[np.ndarray, np.ndarray]] = (), n_samples: int = 20000,
                  cosines: Sequence[float] = COSINES, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(samples [n, 3], counts [len(cosines), n]): per area-uniform sample of the surface, the cameras that
    image it unblocked by the surface itself or the `occluders`, facing it within each cosine. Either side of
    the surface counts: a garment is one sheet, seen from outside or inside."""
    verts = np.asarray(verts, np.float64)
    faces = np.asarray(faces, np.int64)
    points, face = sample_faces(verts, faces, n_samples, np.random.default_rng(seed))
    tri = verts[faces[face]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    caster = RayCaster([(verts, faces), *occluders])
    counts = np.zeros((len(cosines), len(points)), np.int64)
    for cam in cameras:
        to_cam = cam.center - points
        facing = np.einsum("ij,ij->i", normal, to_cam) / np.linalg.norm(to_cam, axis=1)
        uv, z = cam.project(points)
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
        idx = np.flatnonzero(inside & (np.abs(facing) > min(cosines)))
        lifted = points[idx] + LIFT * np.sign(facing[idx])[:, None] * normal[idx]
        seen = idx[~caster.segment_blocked(np.broadcast_to(cam.center, (len(idx), 3)), lifted, eps=0.0)]
        for k, c in enumerate(cosines):
            counts[k, seen[np.abs(facing[seen]) > c]] += 1
    return points, counts


def stereo_coverage(verts: np.ndarray, faces: np.ndarray, cameras: Sequence[Camera],
                    occluders: Sequence[tuple[np.ndarray, np.ndarray]] = (), n_samples: int = 20000) -> dict:
    """Per facing cosine, the percentage of the surface no camera sees and that fewer than two cameras see."""
    _, counts = camera_counts(verts, faces, cameras, occluders, n_samples)
    return {f"cos_{c:g}": {"unseen_pct": float(100.0 * np.mean(n == 0)),
                           "fewer_than_two_pct": float(100.0 * np.mean(n < 2))}
            for c, n in zip(COSINES, counts)}
