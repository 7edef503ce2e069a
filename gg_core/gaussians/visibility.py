"""Visibility of Gaussians in layered outfits: drawn only if nothing else is between them and the camera.

The garment's own Gaussians hide each other through depth-sorted compositing; other meshes (the
body, inner or outer garments) are not splatted, so their occlusion is tested by casting a ray
from the camera centre to each Gaussian's surface point.
"""
from __future__ import annotations

import numpy as np

from ..capture.cameras import Camera
from ..geometry.raycast import RayCaster


def visible_mask(surface_points: np.ndarray, camera: Camera, occluders: RayCaster | None,
                 eps: float = 1e-4) -> np.ndarray:
    """[N] bool: the segment camera centre -> surface point hits no occluder triangle (within eps metres)."""
    points = np.asarray(surface_points, np.float64)
    if occluders is None or len(points) == 0:
        return np.ones(len(points), bool)
    return ~occluders.segment_blocked(camera.center, points, eps)
