"""Triangle surface of a sampled field's zero level (marching cubes), closed and outward-oriented."""
from __future__ import annotations

import numpy as np

from .visual_hull import Grid


def extract_surface(grid: Grid, field: np.ndarray, level: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(verts [V, 3] in world units, faces [F, 3]) of {field = level}, field > level inside.

    The field is padded with an outside layer so that the surface closes where it reaches the grid's border;
    faces are oriented so that normals point out of the region field > level.
    """
    from skimage.measure import marching_cubes  # noqa: PLC0415 - heavy import, only where surfaces are made

    padded = np.pad(np.asarray(field, np.float64), 1, constant_values=min(float(np.min(field)), level) - 1.0)
    if not (padded > level).any():
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    verts, faces, _, _ = marching_cubes(padded, level, spacing=(grid.voxel,) * 3, allow_degenerate=False)
    verts = verts + grid.origin - grid.voxel
    faces = faces.astype(np.int64)
    if signed_volume(verts, faces) < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces


def signed_volume(verts: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed mesh, positive when its normals point outwards."""
    tri = verts[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)
