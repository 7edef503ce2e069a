"""Real spherical harmonics up to degree 3 for view-dependent Gaussian colour.

Basis order and signs are the ones 3D Gaussian splatting uses (and gsplat), so SH
coefficients move between this code, gsplat and exported splat files unchanged.
colour = max(sum_k sh_k * Y_k(view direction) + 0.5, 0).
"""
from __future__ import annotations

import math

import torch

C0 = 0.5 / math.sqrt(math.pi)
C1 = math.sqrt(3 / (4 * math.pi))
C2 = (0.5 * math.sqrt(15 / math.pi), -0.5 * math.sqrt(15 / math.pi), 0.25 * math.sqrt(5 / math.pi),
      -0.5 * math.sqrt(15 / math.pi), 0.25 * math.sqrt(15 / math.pi))
C3 = (-0.25 * math.sqrt(35 / (2 * math.pi)), 0.5 * math.sqrt(105 / math.pi), -0.25 * math.sqrt(21 / (2 * math.pi)),
      0.25 * math.sqrt(7 / math.pi), -0.25 * math.sqrt(21 / (2 * math.pi)), 0.25 * math.sqrt(105 / math.pi),
      -0.25 * math.sqrt(35 / (2 * math.pi)))
MAX_DEGREE = 3


def num_coeffs(degree: int) -> int:
    return (degree + 1) ** 2


def degree_of(num: int) -> int:
    """SH degree of a coefficient count (1, 4, 9 or 16)."""
    for d in range(MAX_DEGREE + 1):
        if num_coeffs(d) == num:
            return d
    raise ValueError(f"{num} SH coefficients per channel is not (d+1)^2 for a degree d <= {MAX_DEGREE}")


def sh_basis(dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """[N, 3] unit directions -> [N, (degree+1)^2] basis values."""
    x, y, z = dirs.unbind(-1)
    out = [torch.full_like(x, C0)]
    if degree >= 1:
        out += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        out += [C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy), C2[3] * x * z, C2[4] * (xx - yy)]
    if degree >= 3:
        out += [C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
                C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy),
                C3[5] * z * (xx - yy), C3[6] * x * (xx - 3 * yy)]
    return torch.stack(out, dim=-1)


def eval_sh(sh: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """RGB [N, 3] of SH coefficients [N, K, 3] seen along directions [N, 3] (normalized here)."""
    degree = degree_of(sh.shape[-2])
    dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    rgb = (sh_basis(dirs, degree)[..., None] * sh).sum(dim=-2)
    return (rgb + 0.5).clamp_min(0.0)


def rgb_to_sh0(rgb: torch.Tensor) -> torch.Tensor:
    """The degree-0 coefficient that reproduces `rgb` from every direction."""
    return (rgb - 0.5) / C0
