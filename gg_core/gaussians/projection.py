"""EWA projection of world Gaussians to screen-space ellipses (torch, differentiable).

Shared by the CPU rasterizer and the tiled-torch benchmark baseline, so both draw exactly the same
ellipses. Conventions: OpenCV camera (x right, y down, z forward), pinhole K (skew allowed),
pixel (col j, row i) samples the point (j + 0.5, i + 0.5). A Gaussian contributes to a pixel iff
its squared Mahalanobis distance d^T conic d <= `support`, where support = min(9, 2 ln(255 o)):
the 3-sigma ellipse intersected with the region where alpha = o exp(-d^T conic d / 2) >= 1/255.
Defining the cut per pixel makes the image independent of the tiling.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .rotations import quat_to_rotmat
from .sh import eval_sh
from .splats import Gaussians

NEAR_PLANE = 0.01       # metres; Gaussians whose centre is closer (or behind the camera) are culled
EPS2D = 0.3             # px^2 added to the 2D covariance (anti-aliasing dilation)
SIGMA_CUT_SQ = 9.0      # 3 sigma
ALPHA_MIN = 1.0 / 255.0
FRUSTUM_MARGIN = 0.15   # the Jacobian is evaluated at most 15 % of the image width beyond its border
EXTENT_SLACK = (1.001, 0.01)  # relative and absolute px margin so rounding never cuts a pixel the test keeps


@dataclass(frozen=True)
class ScreenGaussians:
    """Per-Gaussian screen-space quantities; the first five are differentiable."""

    means2d: torch.Tensor    # [N, 2] pixel coordinates
    conics: torch.Tensor     # [N, 3] (a, b, c): inverse 2D covariance [[a, b], [b, c]]
    depths: torch.Tensor     # [N] camera-space z
    opacities: torch.Tensor  # [N]
    colors: torch.Tensor     # [N, 3]
    support: torch.Tensor    # [N] detached: max squared Mahalanobis distance drawn; <= 0 means never drawn
    extents: torch.Tensor    # [N, 2] detached: half-size in px of the drawn ellipse's bounding box; 0 if culled


def camera_tensors(K: np.ndarray, w2c: np.ndarray, dtype: torch.dtype,
                   device: torch.device | str = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
    return (torch.as_tensor(np.asarray(K, np.float64), dtype=dtype, device=device),
            torch.as_tensor(np.asarray(w2c, np.float64), dtype=dtype, device=device))


def project(gaussians: Gaussians, K: torch.Tensor, w2c: torch.Tensor, width: int, height: int,
            near: float = NEAR_PLANE, eps2d: float = EPS2D) -> ScreenGaussians:
    """Project `gaussians` into a pinhole camera (K [3,3], OpenCV world->camera w2c [4,4])."""
    R, t = w2c[:3, :3], w2c[:3, 3]
    pc = gaussians.means @ R.T + t
    x, y, z = pc.unbind(-1)
    valid = (z > near) & torch.isfinite(pc).all(-1)
    zs = torch.where(valid, z, torch.ones_like(z))
    fx, skew, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    xn, yn = x / zs, y / zs
    means2d = torch.stack((fx * xn + skew * yn + cx, fy * yn + cy), dim=-1)

    # EWA: Jacobian of the perspective map, evaluated at the point clamped to a margin around the
    # frustum so Gaussians far off-screen do not get huge screen footprints.
    mx, my = FRUSTUM_MARGIN * width / fx, FRUSTUM_MARGIN * height / fy
    xc = xn.clamp(float(-cx / fx - mx), float((width - cx) / fx + mx))
    yc = yn.clamp(float(-cy / fy - my), float((height - cy) / fy + my))
    zero = torch.zeros_like(zs)
    J = torch.stack((torch.stack((fx / zs, skew / zs, -(fx * xc + skew * yc) / zs), -1),
                     torch.stack((zero, fy / zs, -fy * yc / zs), -1)), dim=-2)           # [N, 2, 3]
    M = quat_to_rotmat(gaussians.quats) * gaussians.scales[:, None, :]                   # R_g diag(s)
    T = (J @ R) @ M                                                                       # [N, 2, 3]
    cov_a = (T[:, 0] * T[:, 0]).sum(-1) + eps2d
    cov_b = (T[:, 0] * T[:, 1]).sum(-1)
    cov_c = (T[:, 1] * T[:, 1]).sum(-1) + eps2d
    det = cov_a * cov_c - cov_b * cov_b
    conics = torch.stack((cov_c / det, -cov_b / det, cov_a / det), dim=-1)

    if gaussians.sh is not None:
        center = -R.T @ t
        colors = eval_sh(gaussians.sh, gaussians.means - center)
    else:
        colors = gaussians.colors

    with torch.no_grad():
        o = gaussians.opacities
        support = torch.where(o * 255.0 > 1.0, 2.0 * torch.log(o.clamp_min(ALPHA_MIN) * 255.0),
                              torch.full_like(o, -1.0)).clamp(max=SIGMA_CUT_SQ)
        support = torch.where(valid & (det > 0), support, torch.full_like(support, -1.0))
        drawn = support > 0
        s = support.clamp_min(0.0)
        extents = torch.stack((torch.sqrt(s * cov_a), torch.sqrt(s * cov_c)), -1) * EXTENT_SLACK[0] + EXTENT_SLACK[1]
        extents = torch.where(drawn[:, None], extents, torch.zeros_like(extents))
    return ScreenGaussians(means2d, conics, z, gaussians.opacities, colors, support.detach(), extents.detach())

