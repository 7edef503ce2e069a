"""The photometric loss L_rgb = 0.8 L1 + 0.2 (1 - SSIM) over the loss mask, and garment renders with body occlusion.

Pixels outside the loss mask (the body, other clothes) must not pull the garment, and they must not leak
into SSIM windows of nearby garment pixels either: the render is replaced by the target there before both
terms are computed, so ignored pixels contribute nothing and look identical in both images. SSIM uses an
11-pixel Gaussian window with sigma 1.5 (zero padding) and the usual constants for images in [0, 1].
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import torch
import torch.nn.functional as F

from ..gaussians import Gaussians, bind, eval_sh, render, surface_points, visible_mask
from ..gaussians.texture import GaussianTexture
from .views import View

L1_WEIGHT, SSIM_WEIGHT = 0.8, 0.2
SSIM_WINDOW, SSIM_SIGMA = 11, 1.5
_C1, _C2 = 0.01 ** 2, 0.03 ** 2


@lru_cache(maxsize=8)
def _kernel(size: int, sigma: float, dtype: torch.dtype, channels: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Separable normalized Gaussian window as (vertical [C,1,size,1], horizontal [C,1,1,size]) conv weights."""
    x = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    g = torch.exp(-x * x / (2 * sigma * sigma))
    g = (g / g.sum()).to(dtype)
    return (g.view(1, 1, size, 1).expand(channels, 1, size, 1).contiguous(),
            g.view(1, 1, 1, size).expand(channels, 1, 1, size).contiguous())


def _blur(t: torch.Tensor, size: int, sigma: float) -> torch.Tensor:
    """Gaussian blur (zero padding) of [1, C, H, W] as two 1D passes: 5x cheaper than one 2D depthwise conv."""
    wv, wh = _kernel(size, sigma, t.dtype, t.shape[1])
    t = F.conv2d(t, wv, padding=(size // 2, 0), groups=t.shape[1])
    return F.conv2d(t, wh, padding=(0, size // 2), groups=t.shape[1])


def ssim_map(x: torch.Tensor, y: torch.Tensor, size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> torch.Tensor:
    """[H, W] SSIM of two [H, W, 3] images (mean over channels) with a Gaussian window."""
    a, b = x.permute(2, 0, 1), y.permute(2, 0, 1)
    stats = _blur(torch.cat((a, b, a * a, b * b, a * b))[None], size, sigma)[0]
    mu_a, mu_b, aa, bb, ab = stats.split(3)
    var_a, var_b, cov = aa - mu_a ** 2, bb - mu_b ** 2, ab - mu_a * mu_b
    s = ((2 * mu_a * mu_b + _C1) * (2 * cov + _C2)) / ((mu_a ** 2 + mu_b ** 2 + _C1) * (var_a + var_b + _C2))
    return s.mean(0)


def masked_ssim(x: torch.Tensor, y: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mask-weighted mean SSIM of two [H, W, 3] images."""
    return (ssim_map(x, y) * mask).sum() / mask.sum().clamp_min(1e-12)


def rgb_loss(image: torch.Tensor, target: torch.Tensor, mask: torch.Tensor,
             changed: torch.Tensor | None = None) -> torch.Tensor:
    """L_rgb = 0.8 L1 + 0.2 (1 - SSIM) over the pixels weighted by `mask` [H, W] (ignored pixels take the target).

    `changed` [H, W] bool marks every pixel where image and target may differ (e.g. where Gaussians were drawn
    or the garment is seen); both terms are then evaluated on its bounding box grown by one SSIM window only:
    outside it the two images are identical, L1 is 0 and SSIM exactly 1, so the value is the same.
    """
    total = mask.sum().clamp_min(1e-12)
    if changed is not None:
        rows, cols = torch.nonzero(changed.any(1)).flatten(), torch.nonzero(changed.any(0)).flatten()
        if len(rows) == 0:
            return image.sum() * 0.0
        pad = SSIM_WINDOW - 1
        r0, r1 = max(int(rows[0]) - pad, 0), min(int(rows[-1]) + pad + 1, mask.shape[0])
        c0, c1 = max(int(cols[0]) - pad, 0), min(int(cols[-1]) + pad + 1, mask.shape[1])
        outside = total - mask[r0:r1, c0:c1].sum()
        image, target, mask = image[r0:r1, c0:c1], target[r0:r1, c0:c1], mask[r0:r1, c0:c1]
    else:
        outside = total.new_zeros(())
    m = mask[..., None]
    shown = image * m + target * (1 - m)
    l1 = ((shown - target).abs().mean(-1) * mask).sum() / total
    ssim = ((ssim_map(shown, target) * mask).sum() + outside) / total
    return L1_WEIGHT * l1 + SSIM_WEIGHT * (1 - ssim)


def visible_gaussians(texture: GaussianTexture, verts: torch.Tensor, faces: torch.Tensor | np.ndarray,
                      view: View) -> torch.Tensor:
    """[T] bool: Gaussians whose surface point the view's camera sees past the body."""
    points = surface_points(texture, verts.detach(), faces).double().numpy()
    return torch.from_numpy(visible_mask(points, view.camera, view.occluder))


def view_colors(texture: GaussianTexture, verts: torch.Tensor, faces: torch.Tensor | np.ndarray, view: View,
                keep: torch.Tensor) -> torch.Tensor:
    """[K, 3] RGB of the kept Gaussians seen from the view's camera, as constants (no gradient).

    Registration moves the mesh by millimetres per frame, which changes the view directions, and so the SH
    colours, by a negligible amount; evaluating them once per view instead of in every iteration was measured
    to save a fifth of the iteration time with 42k degree-3 Gaussians."""
    with torch.no_grad():
        g = bind(texture, verts.detach(), faces)[keep]
        return eval_sh(g.sh, g.means - torch.as_tensor(view.camera.center, dtype=g.means.dtype))


def render_view(texture: GaussianTexture, verts: torch.Tensor, faces: torch.Tensor | np.ndarray, view: View,
                background: torch.Tensor, params: torch.Tensor | None = None,
                keep: torch.Tensor | None = None, colors: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """Render the garment's Gaussians (those in `keep`, default: visible past the body) over `background`,
    with their SH colours or the given constant `colors` of the kept Gaussians (view_colors)."""
    keep = visible_gaussians(texture, verts, faces, view) if keep is None else keep
    gaussians = bind(texture, verts, faces, params)[keep]
    if colors is not None:
        gaussians = Gaussians(gaussians.means, gaussians.quats, gaussians.scales, gaussians.opacities,
                              colors=colors.to(gaussians.dtype))
    return render(gaussians, view.camera, background=background)


def view_loss(texture: GaussianTexture, verts: torch.Tensor, faces: torch.Tensor | np.ndarray, view: View,
              background: torch.Tensor, params: torch.Tensor | None = None,
              keep: torch.Tensor | None = None,
              colors: torch.Tensor | None = None) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """(L_rgb of one view, the render) for the garment on the mesh `verts`."""
    out = render_view(texture, verts, faces, view, background, params, keep, colors)
    changed = (out["alpha"].detach() > 0) | (view.garment > 0)
    return rgb_loss(out["image"], view.target(background), view.loss_mask, changed), out
