"""SSIM and L_rgb: window, masking, and the cropped evaluation being exact."""
from __future__ import annotations

import torch
import torch.nn.functional as F

from gg_core.registration.photometric import L1_WEIGHT, SSIM_WEIGHT, masked_ssim, rgb_loss, ssim_map


def images(seed: int = 0, h: int = 40, w: int = 30):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(h, w, 3, generator=g, dtype=torch.float64), torch.rand(h, w, 3, generator=g, dtype=torch.float64)


def ssim_reference(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Textbook SSIM with one 2D 11x11 Gaussian window (sigma 1.5), zero padding, mean over channels."""
    r = torch.arange(11, dtype=torch.float64) - 5
    g = torch.exp(-r ** 2 / (2 * 1.5 ** 2))
    w = (g[:, None] * g[None, :] / g.sum() ** 2).expand(3, 1, 11, 11)
    a, b = x.permute(2, 0, 1)[None], y.permute(2, 0, 1)[None]
    mu_a, mu_b = F.conv2d(a, w, padding=5, groups=3), F.conv2d(b, w, padding=5, groups=3)
    va = F.conv2d(a * a, w, padding=5, groups=3) - mu_a ** 2
    vb = F.conv2d(b * b, w, padding=5, groups=3) - mu_b ** 2
    cov = F.conv2d(a * b, w, padding=5, groups=3) - mu_a * mu_b
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return (((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (va + vb + c2)))[0].mean(0)


def test_ssim_matches_the_2d_window_reference_and_is_one_for_equal_images():
    x, y = images()
    assert torch.allclose(ssim_map(x, y), ssim_reference(x, y), atol=1e-12)
    assert torch.allclose(ssim_map(x, x), torch.ones(40, 30, dtype=torch.float64))
    mask = torch.zeros(40, 30, dtype=torch.float64)
    mask[5:20, 3:9] = 1
    assert torch.allclose(masked_ssim(x, y, mask), ssim_reference(x, y)[5:20, 3:9].mean())


def test_ignored_pixels_do_not_change_the_loss():
    x, y = images(1)
    mask = torch.ones(40, 30, dtype=torch.float64)
    mask[10:25, 10:20] = 0                              # e.g. the body
    other = x.clone()
    other[10:25, 10:20] = torch.rand(15, 10, 3, dtype=torch.float64)
    assert torch.allclose(rgb_loss(x, y, mask), rgb_loss(other, y, mask))
    assert float(rgb_loss(y, y, mask)) == 0.0
    # L1 of a constant offset over counted pixels, SSIM term on top
    shifted = (y + 0.1).clamp(max=1.0)
    l1 = ((shifted - y).abs().mean(-1) * mask).sum() / mask.sum()
    ssim = masked_ssim(shifted * mask[..., None] + y * (1 - mask[..., None]), y, mask)
    assert torch.allclose(rgb_loss(shifted, y, mask), L1_WEIGHT * l1 + SSIM_WEIGHT * (1 - ssim))


def test_cropped_evaluation_equals_the_full_image():
    _, target = images(2, 60, 50)
    image = target.clone()
    image[20:30, 15:28] = torch.rand(10, 13, 3, dtype=torch.float64)    # where the garment is drawn
    image.requires_grad_(True)
    mask = torch.ones(60, 50, dtype=torch.float64)
    mask[40:, :] = 0
    changed = torch.zeros(60, 50, dtype=torch.bool)
    changed[20:30, 15:28] = True
    full = rgb_loss(image, target, mask)
    crop = rgb_loss(image, target, mask, changed)
    g_full, = torch.autograd.grad(full, image)
    g_crop, = torch.autograd.grad(crop, image)
    assert abs(float((full - crop).detach())) < 1e-12
    assert torch.allclose(g_full, g_crop, atol=1e-14)
