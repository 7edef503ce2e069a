"""Straightforward float64 reference renderer for exactness tests (numpy, written independently).

Per Gaussian: explicit 3x3 matrices for the covariance and the EWA Jacobian. Per pixel: front-to-back
compositing in depth order, vectorized over pixels but with the same per-pixel rules as the product:
a Gaussian is drawn where d^T conic d <= min(9, 2 ln(255 o)), alpha = min(0.99, o exp(-d^T conic d / 2)),
and a pixel stops before the Gaussian that would take its transmittance below 1e-4.
"""
from __future__ import annotations

import numpy as np


def quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]])


def project_one(mean, quat, scale, K, w2c, width, height, near=0.01, eps2d=0.3):
    """(mean2d, conic 2x2, depth) or None when the Gaussian is culled."""
    R, t = w2c[:3, :3], w2c[:3, 3]
    p = R @ mean + t
    if not p[2] > near:
        return None
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    uvw = K @ p
    mean2d = uvw[:2] / p[2]
    x = np.clip(p[0] / p[2], -cx / fx - 0.15 * width / fx, (width - cx) / fx + 0.15 * width / fx)
    y = np.clip(p[1] / p[2], -cy / fy - 0.15 * height / fy, (height - cy) / fy + 0.15 * height / fy)
    z = p[2]
    J = np.array([[fx / z, s / z, -(fx * x + s * y) / z], [0.0, fy / z, -fy * y / z]])
    Rg = quat_matrix(quat)
    cov3 = Rg @ np.diag(scale ** 2) @ Rg.T
    cov2 = J @ R @ cov3 @ R.T @ J.T + eps2d * np.eye(2)
    return mean2d, np.linalg.inv(cov2), z


def reference_render(means, quats, scales, opacities, colors, K, w2c, width, height, background,
                     return_stopped=False):
    """image [H,W,3], alpha [H,W], depth [H,W] in float64 (+ which pixels hit the transmittance cut-off)."""
    px, py = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    T = np.ones((height, width))
    color = np.zeros((height, width, 3))
    depth = np.zeros((height, width))
    done = np.zeros((height, width), bool)
    items = []
    for i in range(len(means)):
        proj = project_one(means[i], quats[i], scales[i], K, w2c, width, height)
        if proj is not None and opacities[i] * 255 > 1:
            items.append((proj[2], i, proj))
    for _, i, (m2, Q, z) in sorted(items, key=lambda it: (it[0], it[1])):
        dx, dy = m2[0] - px, m2[1] - py
        maha = Q[0, 0] * dx * dx + 2 * Q[0, 1] * dx * dy + Q[1, 1] * dy * dy
        inside = (maha <= min(9.0, 2 * np.log(255 * opacities[i]))) & ~done
        alpha = np.minimum(0.99, opacities[i] * np.exp(-0.5 * maha))
        new_T = T * (1 - alpha)
        stop = inside & (new_T < 1e-4)
        done |= stop
        use = inside & ~stop
        w = np.where(use, alpha * T, 0.0)
        color += w[..., None] * colors[i]
        depth += w * z
        T = np.where(use, new_T, T)
    out = (color + T[..., None] * np.asarray(background), 1 - T, depth)
    return out + (done,) if return_stopped else out


def random_scene(seed: int, n: int = 40, width: int = 40, height: int = 32, extremes: bool = True,
                 opacity: tuple[float, float] = (0.05, 1.0), scale: tuple[float, float] = (0.02, 0.25)) -> dict:
    """Random Gaussians in front of a look-at camera, optionally with the hard cases added:
    behind the camera, crossing the near plane, far off-screen, very thin, very large, nearly transparent.
    High `opacity` makes pixels saturate (alpha clamped at 0.99, transmittance cut-off reached)."""
    from gg_core.capture.cameras import look_at

    rng = np.random.default_rng(seed)
    cam = look_at("c", np.array([0.2, -0.1, -3.0]), np.array([0.0, 0.0, 0.0]), 55, width, height)
    means = rng.uniform([-1.2, -1.0, -0.8], [1.2, 1.0, 0.8], (n, 3))
    scales = np.exp(rng.uniform(np.log(scale[0]), np.log(scale[1]), (n, 3)))
    opacities = rng.uniform(*opacity, n)
    if extremes:
        means[0] = [0.1, 0.0, -4.0]           # behind the camera
        means[1] = [0.3, 0.2, -2.995]         # just in front of the camera centre, inside the near plane
        means[2] = [4.0, 0.5, 0.0]            # far off-screen right
        means[3] = [-0.3, -3.5, 0.5]          # off-screen top, large enough to reach into the image
        scales[3] = [1.0, 1.0, 1.0]
        scales[4] = [0.4, 1e-5, 1e-5]         # very thin needle
        scales[5] = [0.5, 0.3, 1e-6]          # flat disc
        scales[6] = [3.0, 2.0, 2.5]           # very large, covers the whole image
        opacities[6] = 0.3
        opacities[7] = 0.002                  # below 1/255: never drawn
        means[8] = [0.2, -0.1, -2.5]          # close to the camera: huge on screen
    return {"means": means, "quats": rng.normal(size=(n, 4)), "scales": scales, "opacities": opacities,
            "colors": rng.uniform(0, 1, (n, 3)), "camera": cam, "background": rng.uniform(0, 1, 3)}
