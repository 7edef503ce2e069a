"""Visual hull of silhouettes as a signed distance field sampled on a voxel grid.

Each camera's mask becomes a signed pixel distance to the mask outline (positive inside), scaled to metres
by depth / focal length. The hull field is the minimum over the cameras that see a point, so its zero level
is the visual hull with sub-voxel (sub-pixel) accuracy, and |field| never exceeds the 3D distance to the
hull: a voxel whose |field| exceeds its half-diagonal is certainly all inside or all outside, which the
coarse-to-fine bounds search relies on. Cameras that do not see a point (behind it, or the point projects
outside the image) do not constrain it; a point that fewer than half of the cameras see is outside (otherwise
the lone ray cones of single cameras would reach far beyond the subject).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.ndimage import distance_transform_edt

from ..capture.cameras import Camera

OUTSIDE = -1.0        # field value (m) of points too few cameras see
_CHUNK = 1 << 18      # points per projection batch


@dataclass(frozen=True)
class Silhouette:
    """One camera and the signed pixel distance to its mask outline ([H, W], > 0 inside the mask)."""

    camera: Camera
    sdf: np.ndarray

    @classmethod
    def from_mask(cls, camera: Camera, mask: np.ndarray) -> "Silhouette":
        return cls(camera, silhouette_sdf(mask))


def silhouette_sdf(mask: np.ndarray) -> np.ndarray:
    """Signed distance (pixels) from each pixel centre to the outline between mask and non-mask pixels."""
    mask = np.asarray(mask, bool)
    if mask.all():
        return np.full(mask.shape, float(max(mask.shape)))
    if not mask.any():
        return np.full(mask.shape, -float(max(mask.shape)))
    inside = distance_transform_edt(mask) - 0.5
    outside = distance_transform_edt(~mask) - 0.5
    return np.where(mask, inside, -outside)


def bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Sample `image` [H, W, ...] at pixel coordinates (x right, y down, centres at +0.5), clamped at the border."""
    h, w = image.shape[:2]
    fx = np.clip(x - 0.5, 0, w - 1)
    fy = np.clip(y - 0.5, 0, h - 1)
    x0 = np.minimum(fx.astype(np.int64), w - 2) if w > 1 else np.zeros(len(fx), np.int64)
    y0 = np.minimum(fy.astype(np.int64), h - 2) if h > 1 else np.zeros(len(fy), np.int64)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    extra = (slice(None),) + (None,) * (image.ndim - 2)
    ax, ay = (fx - x0)[extra], (fy - y0)[extra]
    top = image[y0, x0] * (1 - ax) + image[y0, x1] * ax
    bottom = image[y1, x0] * (1 - ax) + image[y1, x1] * ax
    return top * (1 - ay) + bottom * ay


def hull_field(points: np.ndarray, silhouettes: Sequence[Silhouette]) -> np.ndarray:
    """[N] signed distance-like value (m) of points to the visual hull: > 0 inside every silhouette that sees them."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.empty(len(points))
    min_views = max(2, -(-len(silhouettes) // 2))
    for s in range(0, len(points), _CHUNK):
        p = points[s:s + _CHUNK]
        field = np.full(len(p), np.inf)
        seen = np.zeros(len(p), np.int64)
        for sil in silhouettes:
            cam = sil.camera
            uv, z = cam.project(p)
            sees = (z > 1e-6) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height)
            idx = np.flatnonzero(sees)
            focal = 0.5 * (cam.K[0, 0] + cam.K[1, 1])
            value = bilinear(sil.sdf, uv[idx, 0], uv[idx, 1]) * z[idx] / focal
            field[idx] = np.minimum(field[idx], value)
            seen[idx] += 1
        out[s:s + len(p)] = np.where(seen >= min_views, field, OUTSIDE)
    return out


@dataclass(frozen=True)
class Grid:
    """Voxel-centre sampling of an axis-aligned box: point (i, j, k) = origin + voxel * (i, j, k)."""

    origin: np.ndarray
    voxel: float
    shape: tuple[int, int, int]

    @classmethod
    def covering(cls, lo: np.ndarray, hi: np.ndarray, voxel: float) -> "Grid":
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        shape = np.maximum(np.ceil((hi - lo) / voxel).astype(np.int64) + 1, 2)
        centre = 0.5 * (lo + hi)
        origin = centre - 0.5 * voxel * (shape - 1)
        return cls(origin, float(voxel), tuple(int(n) for n in shape))

    def points(self) -> np.ndarray:
        axes = [self.origin[d] + self.voxel * np.arange(self.shape[d]) for d in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)

    def sample(self, silhouettes: Sequence[Silhouette], coarse: int = 4) -> np.ndarray:
        """The hull field on the grid, [nx, ny, nz], exact within a narrow band around the hull.

        The field is first sampled every `coarse` voxels; a voxel whose nearest coarse sample lies further from
        the hull than twice the distance between them keeps that sample's value (same sign, and marching
        cubes only reads values next to sign changes); the rest are sampled exactly.
        """
        if coarse <= 1 or min(self.shape) <= 2 * coarse:
            return hull_field(self.points(), silhouettes).reshape(self.shape)
        coarse_grid = Grid(self.origin, self.voxel * coarse, tuple(-(-n // coarse) for n in self.shape))
        rough = coarse_grid.sample(silhouettes, coarse=1)
        nearest = [np.minimum(np.round(np.arange(n) / coarse).astype(np.int64), m - 1)
                   for n, m in zip(self.shape, coarse_grid.shape)]
        field = rough[np.ix_(*nearest)]
        band = np.abs(field) < 2.0 * np.sqrt(3) * 0.5 * coarse * self.voxel
        idx = np.argwhere(band)
        field[band] = hull_field(self.origin + self.voxel * idx, silhouettes)
        return field

    def occupied_bounds(self, field: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Box around every voxel that may hold hull (field above minus the half-diagonal), or None."""
        maybe = np.argwhere(field > -0.5 * np.sqrt(3) * self.voxel)
        if len(maybe) == 0:
            return None
        return (self.origin + self.voxel * (maybe.min(axis=0) - 1),
                self.origin + self.voxel * (maybe.max(axis=0) + 1))


def camera_bounds(cameras: Sequence[Camera]) -> tuple[np.ndarray, np.ndarray]:
    """A box that holds everything the cameras look at together: around the point nearest to all optical axes,
    as wide as the mean camera distance to that point (cameras of a capture surround the subject)."""
    centers = np.array([c.center for c in cameras])
    axes = np.array([c.R[2] for c in cameras])
    # least-squares point closest to the lines centre + s * axis
    proj = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]
    target = np.linalg.lstsq(proj.sum(axis=0), np.einsum("nij,nj->i", proj, centers), rcond=None)[0]
    radius = float(np.mean(np.linalg.norm(centers - target, axis=1)))
    return target - radius, target + radius


def hull_bounds(silhouettes: Sequence[Silhouette], voxel: float, levels: int = 2
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """Tight box around the visual hull by coarse-to-fine sampling from camera_bounds (None if empty)."""
    lo, hi = camera_bounds([s.camera for s in silhouettes])
    for level in range(levels, -1, -1):
        grid = Grid.covering(lo, hi, voxel * 4 ** level)
        box = grid.occupied_bounds(grid.sample(silhouettes))
        if box is None:
            return None
        lo, hi = box
    return lo, hi
