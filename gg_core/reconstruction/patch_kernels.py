"""Photo-consistency's inner loop in one compiled pass: project patch samples into a camera, sample its image and
garment mask bilinearly, and turn each patch into a zero-mean (per colour channel), weighted, unit vector.

Why: done with numpy (Camera.project, visual_hull.bilinear, einsum, norm) the stereo step spent 56 % of its time
in bilinear sampling and 11 % in projection, on temporaries of a million samples per camera and chunk (demo walk,
5 frames, 4 rounds: 6.1 s per frame). The kernel computes the same numbers (float64 inside) without them.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..capture.cameras import Camera


def normalized_patches(points: np.ndarray, camera: Camera, image: np.ndarray, weight: np.ndarray,
                       mask: np.ndarray | None = None) -> np.ndarray:
    """[M, P * 3] float32: the patches at `points` [M, P, 3] as `camera` sees them in `image` [H, W, 3], each
    colour channel centred on its mean weighted by `weight` [P] (times the garment `mask` [H, W] sampled at each
    sample, renormalized, when given), multiplied by the square root of those weights and scaled to unit length
    (lengths below 1e-6 are divided by 1e-6). Image coordinates as in Camera.project and visual_hull.bilinear."""
    m, p = points.shape[:2]
    out = np.empty((m, p * 3), np.float32)
    has_mask = mask is not None
    mask_arr = np.ascontiguousarray(mask, np.float32) if has_mask else np.zeros((1, 1), np.float32)
    _patches(np.ascontiguousarray(points, np.float64).reshape(m, p, 3), np.ascontiguousarray(camera.R, np.float64),
             np.ascontiguousarray(camera.t, np.float64), np.ascontiguousarray(camera.K, np.float64),
             np.ascontiguousarray(image, np.float32), mask_arr, has_mask, np.ascontiguousarray(weight, np.float64),
             out)
    return out


@njit(cache=True, inline="always")
def _corners(x: float, y: float, w: int, h: int) -> tuple[int, int, int, int, float, float]:
    """Bilinear corners and weights of pixel coordinates (centres at +0.5), clamped at the border."""
    fx = min(max(x - 0.5, 0.0), w - 1.0)
    fy = min(max(y - 0.5, 0.0), h - 1.0)
    x0 = min(int(fx), w - 2) if w > 1 else 0
    y0 = min(int(fy), h - 2) if h > 1 else 0
    return x0, y0, min(x0 + 1, w - 1), min(y0 + 1, h - 1), fx - x0, fy - y0


@njit(cache=True)
def _patches(points, R, t, K, image, mask, has_mask, weight, out):
    m, p = points.shape[0], points.shape[1]
    h, w = image.shape[0], image.shape[1]
    colour = np.empty((p, 3))
    wk = np.empty(p)
    for i in range(m):
        total = 0.0
        for k in range(p):
            px, py, pz = points[i, k, 0], points[i, k, 1], points[i, k, 2]
            cx = px * R[0, 0] + py * R[0, 1] + pz * R[0, 2] + t[0]
            cy = px * R[1, 0] + py * R[1, 1] + pz * R[1, 2] + t[1]
            cz = px * R[2, 0] + py * R[2, 1] + pz * R[2, 2] + t[2]
            u = (cx * K[0, 0] + cy * K[0, 1] + cz * K[0, 2]) / cz
            v = (cx * K[1, 0] + cy * K[1, 1] + cz * K[1, 2]) / cz
            x0, y0, x1, y1, ax, ay = _corners(u, v, w, h)
            for c in range(3):
                top = image[y0, x0, c] * (1 - ax) + image[y0, x1, c] * ax
                bottom = image[y1, x0, c] * (1 - ax) + image[y1, x1, c] * ax
                colour[k, c] = top * (1 - ay) + bottom * ay
            wk[k] = weight[k]
            if has_mask:
                mx0, my0, mx1, my1, bx, by = _corners(u, v, mask.shape[1], mask.shape[0])
                top = mask[my0, mx0] * (1 - bx) + mask[my0, mx1] * bx
                bottom = mask[my1, mx0] * (1 - bx) + mask[my1, mx1] * bx
                wk[k] *= top * (1 - by) + bottom * by
            total += wk[k]
        if has_mask:
            total = max(total, 1e-12)
            for k in range(p):
                wk[k] /= total
        norm = 0.0
        for c in range(3):
            mean = 0.0
            for k in range(p):
                mean += colour[k, c] * wk[k]
            for k in range(p):
                colour[k, c] = (colour[k, c] - mean) * np.sqrt(wk[k])
                norm += colour[k, c] * colour[k, c]
        length = max(np.sqrt(norm), 1e-6)
        for k in range(p):
            for c in range(3):
                out[i, k * 3 + c] = colour[k, c] / length
